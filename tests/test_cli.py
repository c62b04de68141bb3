"""The front door: raf --help lists every subcommand, each has its own --help, outputs are well formed."""
import json
import re
import subprocess

import pytest

from robotatfactory.cli import _command_modules, build_parser


def run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300, **kw)


def test_help_lists_every_subcommand(raf_cmd):
    p = run(raf_cmd + ["--help"])
    assert p.returncode == 0
    names = [m.NAME for m in _command_modules()]
    assert {"field", "bench", "experiment", "demo"} <= set(names)
    for name in names:
        assert re.search(rf"^\s+{name}\s", p.stdout, re.M), f"{name} missing from raf --help"


def test_every_subcommand_and_bench_has_help():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name, p in sub.choices.items():
        with pytest.raises(SystemExit) as e:
            parser.parse_args([name, "--help"])
        assert e.value.code == 0
        nested = [a for a in p._actions if getattr(a, "choices", None) and a.dest in ("bench", "experiment")]
        for a in nested:
            for inner in a.choices:
                with pytest.raises(SystemExit) as e:
                    parser.parse_args([name, inner, "--help"])
                assert e.value.code == 0


def test_unknown_field_is_a_clear_error(raf_cmd):
    p = run(raf_cmd + ["--field", "nosuch", "field"])
    assert p.returncode == 2
    assert "unknown field 'nosuch'" in p.stderr and "Traceback" not in p.stderr


def test_field_png_and_json(raf_cmd, tmp_path):
    png = tmp_path / "f.png"
    p = run(raf_cmd + ["field", "--png", str(png)])
    assert p.returncode == 0, p.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 50_000
    p = run(raf_cmd + ["--field", "simtwo2022", "field", "--json"])
    markers = json.loads(p.stdout)
    assert len(markers) == 45 and {m["size"] for m in markers if m["id"] >= 50} == {0.055}  # 62-65: mirrored in SimTwo


def test_bench_protocol_writes_flat_json_with_units(raf_cmd, tmp_path):
    out = tmp_path / "p.json"
    p = run(raf_cmd + ["bench", "protocol", "--seconds", "0.05", "--repeats", "1", "--json", str(out)])
    assert p.returncode == 0, p.stderr
    assert "sensor_frame_decode_frames_per_s" in p.stdout
    res = json.loads(out.read_text())
    assert all(not isinstance(v, (dict, list)) for v in res.values())
    assert res["sensor_frame_rays"] == 360 and res["sensor_frame_decode_frames_per_s"] > 0


def test_bootstrap_second_run_installs_nothing():
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    p = run(["bash", str(root / "scripts/bootstrap.sh")])
    assert p.returncode == 0, p.stderr
    assert "ready" in p.stdout and "installing" not in p.stdout
