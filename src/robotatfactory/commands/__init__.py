"""``raf`` subcommands, one module each (see :mod:`robotatfactory.cli`)."""
