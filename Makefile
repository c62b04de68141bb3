# Conveniences; the README's two commands call scripts/bootstrap.sh directly (a fresh Debian has no make).
.PHONY: setup demo test bench
setup:
	bash scripts/bootstrap.sh
demo:
	bash scripts/bootstrap.sh demo
test:
	bash scripts/bootstrap.sh test
bench:
	bash scripts/bootstrap.sh && for b in protocol sim bridge localization; do .venv/bin/raf bench $$b --json out/bench/$$b.json; done
