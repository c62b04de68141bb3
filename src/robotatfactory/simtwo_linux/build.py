"""Build the real SimTwo from pinned sources: ``raf simtwo build``.

Steps (each failure is a :class:`BuildError` that names the step and why):

1. **packages**: the Debian packages the build needs are installed (:data:`DEBIAN_PACKAGES`);
2. **sources**: each pinned source (``simtwo/linux/sources.json``) from an archive in ``--sources DIR``
   (checked against its sha256) or, without one, a git clone at the pinned commit;
3. **patches**: ``simtwo/linux/patches/*.patch`` applied in order (``git apply``), and the Linux stand-in
   units (``simtwo/linux/units/*.pas``) copied to ``SimTwo/platform/linux/``;
4. **lazbuild**: the five Lazarus packages registered in a private configuration (``--pcp``, never the
   user's ``~/.lazarus``), then ``lazbuild --ws=gtk2 SimTwo.lpi``.

The result lives in ``build/simtwo/<key>/`` where the key hashes everything the build depends on (the pins,
the patches, the units, the compiler's and Lazarus's versions): a second build when nothing changed finds it
and returns at once.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import tarfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parents[3]  # the repository
LINUX_DIR = ROOT / "simtwo" / "linux"
BUILD_ROOT = ROOT / "build" / "simtwo"
LAZARUS_ROOT = Path("/usr/lib/lazarus")

#: Debian packages the build needs (beyond what the bootstrap installs for the rest of the project). Also
#: in scripts/bootstrap.sh's list; a test checks the two agree.
DEBIAN_PACKAGES = (
    "fp-compiler", "fp-units-base", "fp-units-fcl", "fp-units-gfx", "fp-units-gtk2", "fp-units-misc",
    "fp-units-net", "fp-units-db", "fp-units-math", "fp-units-fv",
    "lazarus-src-2.2", "lazarus-ide-2.2", "lcl-2.2", "lcl-gtk2-2.2", "lcl-units-2.2", "lcl-utils-2.2",
    "libgtk2.0-dev", "libode-dev", "libzmq3-dev", "git",
)

Progress = Callable[[str], None]


class BuildError(RuntimeError):
    """A build step failed: ``step`` names it, the message says why."""

    def __init__(self, step: str, why: str):
        super().__init__(f"{step}: {why}")
        self.step = step


@dataclass(frozen=True)
class Build:
    """A finished build: the SimTwo tree (scenes, executable) and how it was made."""

    dir: Path           # build/simtwo/<key>
    simtwo_dir: Path    # the SimTwo source tree, with the executable and the scene folders
    executable: Path
    seconds: float      # how long this call took (0.x when cached)
    cached: bool

    def scene_dir(self, scene: str) -> Path:
        return self.simtwo_dir / scene


def spec() -> dict:
    return json.loads((LINUX_DIR / "sources.json").read_text())


def patches(source: str | None = None) -> list[Path]:
    """The patches of one source (``SimTwo``, ``5dpo_lazarus``, ...; sources.json's ``patches`` folder), in
    the order they apply; without ``source``, every source's."""
    out = []
    for src in spec()["sources"]:
        if src.get("patches") and source in (None, src["name"]):
            out += sorted((LINUX_DIR / src["patches"]).glob("*.patch"))
    return out


def units() -> list[Path]:
    return sorted((LINUX_DIR / "units").glob("*.pas"))


def _run(cmd: list[str], step: str, cwd: Path | None = None, log: Path | None = None,
         env: dict | None = None) -> str:
    try:
        r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, errors="replace", env=env)
    except FileNotFoundError:
        raise BuildError(step, f"{cmd[0]} is not installed") from None
    out = r.stdout + r.stderr
    if log is not None:
        with open(log, "a") as f:
            f.write(f"$ {' '.join(cmd)}\n{out}\n")
    if r.returncode != 0:
        raise BuildError(step, f"`{' '.join(cmd)}` failed (exit {r.returncode}):\n{_tail(out)}")
    return out


def _tail(text: str, n: int = 15) -> str:
    return "\n".join(text.strip().splitlines()[-n:])


def missing_packages() -> list[str]:
    """The Debian packages of :data:`DEBIAN_PACKAGES` that are not installed."""
    try:
        r = subprocess.run(["dpkg-query", "-W", "-f=${Package} ${Status}\n", *DEBIAN_PACKAGES],
                           capture_output=True, text=True)
    except FileNotFoundError:
        return []  # not a Debian system: the compiler's own errors will tell
    ok = {line.split()[0] for line in r.stdout.splitlines() if line.endswith("install ok installed")}
    return [p for p in DEBIAN_PACKAGES if p not in ok]


def lazarus_dir() -> Path:
    """Debian's Lazarus tree (/usr/lib/lazarus/2.2.6)."""
    # the versioned folder ("default" is Debian's alternatives link to it)
    found = sorted({d.resolve() for d in LAZARUS_ROOT.glob("*") if (d / "lcl").is_dir()}
                   if LAZARUS_ROOT.is_dir() else [])
    if not found:
        raise BuildError("packages", f"no Lazarus under {LAZARUS_ROOT} (apt-get install lazarus-ide-2.2 lcl-2.2)")
    return found[-1]


def tool_versions() -> str:
    """The compiler's and Lazarus's versions (part of the cache key)."""
    try:
        fpc = subprocess.run(["fpc", "-iV"], capture_output=True, text=True).stdout.strip()
    except FileNotFoundError:
        fpc = "none"
    try:
        laz = lazarus_dir().name
    except BuildError:
        laz = "none"
    return f"fpc {fpc}; lazarus {laz}"


def cache_key() -> str:
    """A hash of everything the build depends on: the pins, the patches, the units, the tools' versions and
    this module's recipe."""
    h = hashlib.sha256()
    h.update((LINUX_DIR / "sources.json").read_bytes())
    for p in patches() + units():
        h.update(p.name.encode() + b"\0" + p.read_bytes())
    h.update(tool_versions().encode())
    h.update(Path(__file__).read_bytes())
    return h.hexdigest()[:16]


def find(key: str | None = None) -> Build | None:
    """The finished build for the current inputs, or None."""
    d = BUILD_ROOT / (key or cache_key())
    s = spec()
    exe = d / "src" / s["executable"]
    if (d / "ok").exists() and exe.exists():
        return Build(d, exe.parent, exe, 0.0, True)
    return None


def require() -> Build:
    """The finished build, or a BuildError that says how to make it."""
    b = find()
    if b is None:
        raise BuildError("build", "SimTwo is not built for the current sources and patches: run "
                                  "`raf simtwo build --sources DIR` (e.g. DIR = ../shared/vendor/simtwo) "
                                  "or scripts/bootstrap.sh")
    return b


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _fetch(src: dict, sources: Path | None, dest: Path, log: Path, progress: Progress) -> None:
    """Put source ``src`` at ``dest/src['name']``: from its archive in ``sources`` or a git clone."""
    name = src["name"]
    archive = sources / src["archive"] if sources else None
    if archive is not None and archive.exists():
        got = _sha256(archive)
        if got != src["sha256"]:
            raise BuildError("sources", f"{archive}: sha256 {got}, expected {src['sha256']} (not the pinned "
                                        f"commit {src['commit'][:7]})")
        progress(f"sources: {archive.name} (sha256 ok)")
        _extract(archive, dest)
        if not (dest / name).is_dir():
            raise BuildError("sources", f"{archive} has no folder {name}/ at its top")
        return
    if sources is not None:
        progress(f"sources: {src['archive']} is not in {sources}; cloning {src['repository']}")
    else:
        progress(f"sources: cloning {src['repository']} at {src['commit'][:7]}")
    target = dest / name
    try:
        _run(["git", "clone", "--quiet", "--no-checkout", src["repository"], str(target)], "sources", log=log)
        _run(["git", "-C", str(target), "checkout", "--quiet", src["commit"]], "sources", log=log)
    except BuildError as e:
        raise BuildError("sources", f"no archive of {name} and git could not clone it ({e}); pass "
                                    f"--sources DIR with {src['archive']} (e.g. ../shared/vendor/simtwo)") from None


def _extract(archive: Path, dest: Path) -> None:
    """Unpack ``archive`` into ``dest``, refusing members that would land outside it or are links out of it
    (Debian 12's Python 3.11.2 has no tarfile filters)."""
    root = dest.resolve()
    with tarfile.open(archive) as t:
        members = t.getmembers()
        for m in members:
            target = (root / m.name).resolve()
            if not target.is_relative_to(root) or m.isdev() or (m.issym() or m.islnk()) and (
                    os.path.isabs(m.linkname) or not (target.parent / m.linkname).resolve().is_relative_to(root)):
                raise BuildError("sources", f"{archive.name}: member {m.name!r} points outside the build folder")
        t.extractall(dest, members)


def first_compiler_error(log_text: str) -> str:
    """The compiler's first error (file(line,col) Error/Fatal: ...) in lazbuild's output, else its tail."""
    for line in log_text.splitlines():
        if re.search(r"\) (Error|Fatal): ", line) and "Compilation aborted" not in line:
            return line.strip()
    for line in log_text.splitlines():
        if re.search(r"\b(Error|Fatal):", line):
            return line.strip()
    return _tail(log_text)


def build(sources: Path | None = None, progress: Progress = lambda _m: None, force: bool = False) -> Build:
    """Build SimTwo (or find it built). ``sources``: a directory with the pinned archives; None: git."""
    t0 = time.monotonic()
    key = cache_key()
    if not force:
        b = find(key)
        if b is not None:
            return Build(b.dir, b.simtwo_dir, b.executable, time.monotonic() - t0, True)
    missing = missing_packages()
    if missing:
        raise BuildError("packages", f"missing Debian packages: {' '.join(missing)} (apt-get install "
                                     f"{' '.join(missing)}, or run scripts/bootstrap.sh)")
    s = spec()
    out = BUILD_ROOT / key
    if out.exists():
        shutil.rmtree(out)
    src_dir = out / "src"
    src_dir.mkdir(parents=True)
    log = out / "build.log"
    for src in s["sources"]:
        _fetch(src, Path(sources) if sources else None, src_dir, log, progress)

    # build/ lies inside the project's own git checkout: without a ceiling, git apply would take the paths as
    # the project's and silently skip them
    git_env = dict(os.environ, GIT_CEILING_DIRECTORIES=str(src_dir))
    for src in s["sources"]:
        plist = patches(src["name"])
        if plist:
            progress(f"patches: {src['name']}: applying {len(plist)} ({plist[0].stem} .. {plist[-1].stem})")
        for p in plist:
            try:
                _run(["git", "apply", "--whitespace=nowarn", str(p)], "patches", cwd=src_dir / src["name"],
                     log=log, env=git_env)
            except BuildError as e:
                raise BuildError("patches", f"{p.parent.name}/{p.name} does not apply to {src['name']} at "
                                            f"{src['commit'][:7]}: {e}") from None
    simtwo = src_dir / "SimTwo"
    plat = simtwo / "platform" / "linux"
    plat.mkdir(parents=True)
    for u in units():
        shutil.copy2(u, plat / u.name)

    laz = lazarus_dir()
    pcp = out / "lazarus-config"  # a private lazbuild configuration, never ~/.lazarus
    progress(f"lazbuild: registering {len(s['lazarus_packages'])} Lazarus packages in {pcp}")
    for lpk in s["lazarus_packages"]:
        _run(["lazbuild", f"--pcp={pcp}", f"--lazarusdir={laz}", "--add-package-link", str(src_dir / lpk)],
             "lazbuild", log=log)
    progress("lazbuild: compiling SimTwo (GLScene, lNet, PascalScript and SimTwo: 0.5-2 minutes the first time)")
    r = subprocess.run(["lazbuild", f"--pcp={pcp}", f"--lazarusdir={laz}", "--ws=gtk2", "-q",
                        str(src_dir / s["project"])], capture_output=True, text=True, errors="replace")
    with open(log, "a") as f:
        f.write(r.stdout + r.stderr)
    exe = src_dir / s["executable"]
    if r.returncode != 0 or not exe.exists():
        raise BuildError("lazbuild", f"SimTwo did not compile: {first_compiler_error(r.stdout + r.stderr)} "
                                     f"(whole log: {log})")
    (out / "ok").write_text(json.dumps({"key": key, "tools": tool_versions(), "seconds": time.monotonic() - t0,
                                        "sources": str(sources) if sources else "git"}) + "\n")
    _prune(keep=key)
    return Build(out, exe.parent, exe, time.monotonic() - t0, False)


def _prune(keep: str) -> None:
    """Remove builds of other inputs (each is ~300 MB)."""
    for d in BUILD_ROOT.iterdir():
        if d.is_dir() and d.name != keep and re.fullmatch(r"[0-9a-f]{16}", d.name):
            shutil.rmtree(d, ignore_errors=True)


def default_sources() -> Path | None:
    """``$RAF_SIMTWO_SOURCES``, else ``../shared/vendor/simtwo`` beside the repository when it exists."""
    env = os.environ.get("RAF_SIMTWO_SOURCES")
    if env:
        return Path(env)
    d = ROOT.parent / "shared" / "vendor" / "simtwo"
    return d if d.is_dir() else None
