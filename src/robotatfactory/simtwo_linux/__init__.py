"""The real SimTwo on Linux: built from pinned sources with the project's patches, and run headless.

SimTwo's authors ship Windows builds only; it is a Lazarus program and builds on Debian 12 with Debian's
Lazarus 2.2.6 and Free Pascal 3.2.2 plus the small source changes in ``simtwo/linux/`` (docs/simtwo.md,
"SimTwo on Linux"). No ROS here:

- :mod:`.build`: the sources (an archive directory or git), the patches, lazbuild with a private
  configuration, cached under ``build/simtwo/``;
- :mod:`.scene`: a fresh copy of a scene with the project's ``control.pas``, LIDAR and settings installed as
  docs/simtwo.md tells a Windows user to;
- :mod:`.run`: SimTwo under its own Xvfb, its own ports, the camera window opened, stopped with everything
  it started.
"""
