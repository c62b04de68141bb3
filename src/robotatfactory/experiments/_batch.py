"""Running a batch of independent runs: on this machine (threads, or a pool of processes) or on a Ray cluster.

    runs, info = execute(job, items, jobs=2, local="processes", ray="HOST:PORT", failed=...)

``job(item, out_dir) -> dict`` plays one run and returns its flat figures; it must be picklable (a module-level
function or a :func:`functools.partial` of one) and should not raise: a run that fails returns what ``failed(item,
exc)`` gives (the competition's ``_failed``). ``runs`` come back in the order of ``items``; ``info`` names the
executor (``executor`` ``local`` or ``ray``, ``runs_retried``, on Ray also ``ray_workers``, ``ray_nodes_used``
...). A progress line (:class:`._progress.BatchProgress`) counts the runs on a terminal either way.

Locally (``ray`` None), as ``raf experiment competition`` always ran: ``local="threads"``: a thread per run,
``jobs`` at once (the whole stack: each run is its own processes); ``local="processes"``: ``jobs`` spawned
processes (the bare stand-in runs in the process), or serially in this one when ``jobs`` is 1 or there is one
item.

On Ray (``ray`` an address: ``HOST:PORT`` of a cluster's head, ``auto`` for the cluster this machine belongs to,
``local`` for a private one-machine instance of ``jobs`` CPUs; passed to ``ray.init``): each run is
a Ray task reserving ``ray_cpus`` CPUs on some node; the cluster's CPUs decide how many run at once. Ray is
imported here only then. What a run needs from this (the driver's) process travels with it:

- the ``RAF_*`` settings of the environment (:data:`SHIPPED_ENV`: the middleware ...), set around the run;
- input files (``inputs``: e.g. a ``--field`` file, a ``--calibration`` YAML): their bytes, written on the
  worker and the paths in ``job`` and ``item`` pointed at them;
- ``out_dir``: the run writes into a private directory on its worker, whose files come back with the result
  and are written under the driver's ``out_dir`` (paths in the result are rewritten to match): no shared
  filesystem is needed.

The code itself does not travel: every machine runs its own checkout, which must be the same version (each
result carries the worker's :func:`code_fingerprint`; one differing from the driver's is counted and warned
about).

A run whose worker process or node is lost (``WorkerCrashedError``, ``NodeDiedError``, an object lost with it,
the node out of memory: :data:`LOST`) is submitted again, wherever Ray places it, up to ``ray_retries`` times;
its result records ``attempts`` and what was lost (``lost_attempts``). A run that raised inside Python is not
retried: Ray's ``RayTaskError`` is a failed run (``failed``), as locally. Ray's own retries are off
(``max_retries=0``) so that this loop knows and reports every attempt.
"""
from __future__ import annotations

import functools
import hashlib
import os
import shutil
import signal
import socket
import sys
import tempfile
import time
import zlib
from collections import deque
from pathlib import Path, PurePath
from typing import Callable, Iterable

ROOT = Path(__file__).resolve().parents[3]  # the repository (src/robotatfactory/experiments/_batch.py)
#: settings of the environment a run reads, given to each Ray task as the driver has them (paths are not: a
#: worker's own checkout and virtual environments are where its machine has them)
SHIPPED_ENV = ("RAF_MIDDLEWARE", "RAF_ROS2_EXECUTOR")
#: Ray's exceptions for a run lost with its worker process or node (retried), by name: ray is imported lazily
LOST = ("WorkerCrashedError", "NodeDiedError", "ObjectLostError", "OutOfMemoryError")
RAY_RETRIES = 2  # a lost run is submitted again up to this many times (3 attempts in all)


def execute(job: Callable, items: Iterable, *, jobs: int = 2, local: str = "processes",
            out_dir: Path | None = None, failed: Callable | None = None, label: Callable | None = None,
            ray: str | None = None, ray_cpus: float = 1, ray_retries: int = RAY_RETRIES,
            inputs: Iterable[str | Path] = (), progress: Callable | None = None) -> tuple[list[dict], dict]:
    """Run ``job(item, out_dir)`` for every item; (runs in the order of ``items``, executor info). See the module
    docstring. ``label(item)`` names an item in messages (default ``str``); ``progress(total, jobs)`` makes the
    progress line (default :class:`._progress.BatchProgress`)."""
    from ._progress import BatchProgress

    items = list(items)
    progress = progress or BatchProgress
    if ray:
        return _ray_execute(job, items, address=str(ray), jobs=jobs, out_dir=out_dir, failed=failed,
                            label=label or str, cpus=ray_cpus, retries=ray_retries, inputs=inputs,
                            progress=progress)
    if local not in ("threads", "processes"):
        raise ValueError(f"local={local!r}: threads or processes")
    jobs = max(1, int(jobs))
    bar = progress(len(items), jobs)
    one = functools.partial(job, out_dir=out_dir)
    if local == "threads":  # each run is its own processes: a thread per run waits on them
        from concurrent.futures import ThreadPoolExecutor

        def run(item):
            bar.start()
            r = one(item)
            bar.finish("error" not in r)
            return r

        with ThreadPoolExecutor(max_workers=max(1, min(jobs, len(items)))) as pool:
            runs = list(pool.map(run, items))
    elif jobs == 1 or len(items) <= 1:
        runs = []
        for item in items:
            bar.start()
            runs.append(one(item))
            bar.finish("error" not in runs[-1])
    else:
        import multiprocessing as mp

        n = min(jobs, len(items))
        with mp.get_context("spawn").Pool(n) as pool:
            runs = []
            bar.finish(None, running=n)  # the pool's workers start at once
            for r in pool.imap(one, items, chunksize=1):  # in order, each as it ends
                runs.append(r)
                bar.finish("error" not in r, running=min(n, len(items) - len(runs)))
    bar.close()
    return runs, {"executor": "local", "runs_retried": 0}


# ------------------------------------------------------------------------------------------------------ Ray
def import_ray():
    """The ``ray`` module, or ConfigError saying how to get it."""
    from ..errors import ConfigError

    try:
        import ray
    except ImportError:
        raise ConfigError(f"--ray: Ray is not installed in this Python ({sys.executable}); it is pinned in "
                          "requirements.txt (scripts/bootstrap.sh installs it into .venv)") from None
    return ray


def connect(address: str, cpus: int = 2) -> bool:
    """Connect this process to the Ray cluster at ``address`` (``local``: start a private instance of ``cpus``
    CPUs); False when it already was connected (then that connection is used and left open), True when the
    caller should ``ray.shutdown()`` at the end."""
    import logging

    from ..errors import ConfigError

    ray = import_ray()
    if ray.is_initialized():
        return False
    kw: dict = {"address": address, "logging_level": logging.WARNING, "log_to_driver": False}
    if address == "local":
        kw.update(num_cpus=max(1, int(cpus)), include_dashboard=False)
    try:
        ray.init(**kw)
    except (ConnectionError, RuntimeError, ValueError) as e:
        raise ConfigError(f"--ray {address}: cannot connect: {type(e).__name__}: {e}") from None
    return True


def cluster() -> list[dict]:
    """The cluster's alive nodes: ``{"id", "host", "cpus"}`` each."""
    import ray

    return [{"id": n["NodeID"], "host": n.get("NodeManagerHostname") or n.get("NodeManagerAddress", "?"),
             "cpus": float(n.get("Resources", {}).get("CPU", 0.0))} for n in ray.nodes() if n.get("Alive")]


def _ray_execute(job, items, *, address, jobs, out_dir, failed, label, cpus, retries, inputs,
                 progress) -> tuple[list[dict], dict]:
    from ..errors import ConfigError

    ray = import_ray()
    if failed is None:
        raise ValueError("execute(ray=...): failed(item, exc) is needed to report a run Ray could not give back")
    cpus = float(cpus)
    if cpus <= 0:
        raise ConfigError("--ray-cpus must be > 0")
    shipped = {str(Path(p).resolve()): Path(p).read_bytes() for p in inputs}
    t0 = time.perf_counter()
    own = connect(address, jobs)
    connect_s = time.perf_counter() - t0
    inflight: dict = {}
    try:
        nodes = cluster()
        slots = sum(int(n["cpus"] // cpus) for n in nodes)
        if not slots:
            raise ConfigError(f"--ray {address}: no node of the cluster has {cpus:g} CPUs for a run (nodes: "
                              + (", ".join(f"{n['host']} {n['cpus']:g} CPUs" for n in nodes) or "none") + ")")
        mine = code_fingerprint()
        env = {k: os.environ[k] for k in SHIPPED_ENV if k in os.environ}
        remote = ray.remote(_remote_run).options(num_cpus=cpus, max_retries=0, retry_exceptions=False)
        lost_types = tuple(getattr(ray.exceptions, n) for n in LOST)
        job_ref, shipped_ref = ray.put(job), ray.put(shipped)  # once, not with every task
        bar = progress(len(items), slots)
        runs: list = [None] * len(items)
        attempts = [0] * len(items)
        lost: list[list[str]] = [[] for _ in items]
        pending = deque(range(len(items)))
        mismatched = 0
        while pending or inflight:
            while pending and len(inflight) < slots:
                i = pending.popleft()
                attempts[i] += 1
                inflight[remote.remote(job_ref, items[i], out_dir is not None, shipped_ref, env)] = i
            bar.finish(None, running=len(inflight))
            ready, _ = ray.wait(list(inflight), num_returns=1)
            for ref in ready:
                i = inflight.pop(ref)
                try:
                    got = ray.get(ref)
                except lost_types as e:
                    what = f"{type(e).__name__}: {_first_line(e)}"
                    lost[i].append(what)
                    if attempts[i] <= retries:
                        print(f"ray: {label(items[i])}: lost with its worker ({what}); submitted again (attempt "
                              f"{attempts[i] + 1} of {retries + 1})", file=sys.stderr, flush=True)
                        pending.appendleft(i)
                        continue
                    r = failed(items[i], e)
                except ray.exceptions.RayTaskError as e:  # raised inside Python: a failed run, not retried
                    cause = getattr(e, "cause", None)
                    r = failed(items[i], cause if isinstance(cause, BaseException) else e)
                except ray.exceptions.RayError as e:  # anything else Ray could not do: failed, reported
                    r = failed(items[i], e)
                else:
                    r = got["run"]
                    if out_dir is not None and got["out"]:
                        _unpack(got["files"], Path(out_dir))
                        r = _swap(r, {got["out"]: str(out_dir)})
                    r.update(ray_node=got["node"], ray_host=got["host"], ray_pid=got["pid"])
                    if got["code"] != mine:
                        mismatched += 1
                        r["ray_code_differs"] = True
                r["attempts"] = attempts[i]
                if lost[i]:
                    r["lost_attempts"] = list(lost[i])
                runs[i] = r
                bar.finish("error" not in r, running=len(inflight))
        bar.close()
    except BaseException:
        for ref in inflight:  # Ctrl-C or a driver error: stop what still runs on the cluster
            try:
                ray.cancel(ref, force=True)
            except Exception:  # noqa: BLE001 - best effort on the way out
                pass
        raise
    finally:
        if own:
            ray.shutdown()
    if mismatched:
        print(f"ray: warning: {mismatched} run(s) ran code that differs from this checkout's (ray_code_differs in "
              "runs.json): every machine needs the same version", file=sys.stderr, flush=True)
    used = sorted({r["ray_node"] for r in runs if "ray_node" in r})
    per_node = {n: sum(r.get("ray_node") == n for r in runs) for n in used}
    return runs, {
        "executor": "ray", "ray_address": address, "ray_version": ray.__version__,
        "ray_nodes": len(nodes), "ray_cpus": sum(n["cpus"] for n in nodes), "ray_cpus_per_run": cpus,
        "ray_workers": slots, "ray_nodes_used": len(used),
        "ray_runs_per_node": ", ".join(f"{n[:8]} ({_host(runs, n)}): {k}" for n, k in per_node.items()),
        "ray_connect_s": round(connect_s, 2),
        "runs_retried": sum(a > 1 for a in attempts), "run_attempts": sum(attempts),
        "runs_lost": sum(bool(lost[i]) and "ray_node" not in runs[i] for i in range(len(items))),
        "ray_code_differs_runs": mismatched,
    }


def _host(runs: list[dict], node: str) -> str:
    return next((r["ray_host"] for r in runs if r.get("ray_node") == node), "?")


def _first_line(e: BaseException) -> str:
    s = str(e).strip().splitlines()
    return s[0][:200] if s else ""


def _remote_run(job, item, collect: bool, shipped: dict, env: dict) -> dict:
    """One run in a Ray worker: the driver's input files and settings put in place, its output in a private
    directory whose files go back with the result."""
    import ray

    _sweep()
    work = Path(tempfile.mkdtemp(prefix=f"raf-batch-{os.getpid()}-"))
    try:
        where = {}
        for k, (path, data) in enumerate(shipped.items()):  # the driver's input files, here
            p = work / "inputs" / f"{k}_{PurePath(path).name}"
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_bytes(data)
            where[path] = str(p)
        out = work / "out" if collect else None
        if out is not None:
            out.mkdir()
        saved = {k: os.environ.get(k) for k in SHIPPED_ENV}
        # Ray's worker blocks SIGINT, and a blocked signal stays blocked in every child it starts: the whole
        # stack's nodes would not hear the SIGINT that stops them (raf record killed later, its bag unindexed)
        mask = signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
        try:
            for k in SHIPPED_ENV:
                if k in env:
                    os.environ[k] = env[k]
                else:
                    os.environ.pop(k, None)
            run = _swap(job, where)(_swap(item, where), out_dir=out)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        files = _pack(out) if out is not None else {}
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return {"run": run, "files": files, "out": str(out) if out is not None else "",
            "node": ray.get_runtime_context().get_node_id(), "host": socket.gethostname(), "pid": os.getpid(),
            "code": code_fingerprint()}


def _sweep() -> None:
    """Remove the private directories of runs whose worker process died (killed: it could not remove its own)."""
    for d in Path(tempfile.gettempdir()).glob("raf-batch-*-*"):
        try:
            pid = int(d.name.split("-")[2])
        except (IndexError, ValueError):
            continue
        if pid != os.getpid() and not _alive(pid):
            shutil.rmtree(d, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[-1].split()[0]
    except (OSError, IndexError):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True
    return state != "Z"  # a zombie is dead


def _swap(obj, where: dict):
    """``obj`` with every string (or path) that is one of ``where``'s keys, or under one as a directory, pointing
    at its value instead; through tuples, lists, dicts and :func:`functools.partial`."""
    if not where:
        return obj
    if isinstance(obj, str):
        for old, new in where.items():
            if obj == old or obj.startswith(old.rstrip("/") + "/"):
                return new + obj[len(old):]
        return obj
    if isinstance(obj, PurePath):
        return type(obj)(_swap(str(obj), where))
    if isinstance(obj, functools.partial):
        return functools.partial(_swap(obj.func, where), *_swap(obj.args, where), **_swap(obj.keywords, where))
    if isinstance(obj, tuple):
        return tuple(_swap(x, where) for x in obj)
    if isinstance(obj, list):
        return [_swap(x, where) for x in obj]
    if isinstance(obj, dict):
        return {k: _swap(v, where) for k, v in obj.items()}
    return obj


def _pack(d: Path) -> dict[str, bytes]:
    """The regular files under ``d``: ``{relative path: zlib-compressed bytes}``."""
    out = {}
    for p in sorted(d.rglob("*")):
        if p.is_file() and not p.is_symlink():
            out[p.relative_to(d).as_posix()] = zlib.compress(p.read_bytes(), 3)
    return out


def _unpack(files: dict[str, bytes], d: Path) -> None:
    """Write :func:`_pack`'s files under ``d`` (a name leaving ``d`` is refused)."""
    for rel, data in files.items():
        parts = PurePath(rel).parts
        if PurePath(rel).is_absolute() or ".." in parts or not parts:
            raise ValueError(f"a run's output file {rel!r} is outside its directory")
        p = d.joinpath(*parts)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(zlib.decompress(data))


def probe(item: dict, out_dir: Path | None = None) -> dict:
    """A job that plays no round, for the tests and ``raf bench batch`` (what the executor itself costs and
    carries): sleeps ``item["sleep"]`` s, reads the file ``item["read"]``, writes ``item["write"]``
    (``{relative path: text}``) under ``out_dir``, raises ValueError with ``item["raise"]``; returns what it saw
    (``read`` text, ``out`` paths written, ``env``: the :data:`SHIPPED_ENV` settings, ``host``, ``pid``, with
    ``item["child_signals"]`` the signal masks a child process starts with)."""
    if item.get("raise"):
        raise ValueError(item["raise"])
    time.sleep(float(item.get("sleep", 0.0)))
    out = {"round": item.get("round", 0), "seed": item.get("seed", 0), "host": socket.gethostname(),
           "pid": os.getpid(), "env": {k: os.environ[k] for k in SHIPPED_ENV if k in os.environ}}
    if item.get("read"):
        out["read"] = Path(item["read"]).read_text()
    if item.get("child_signals"):  # the signals a child process starts with blocked / ignored (hex masks)
        import subprocess

        status = subprocess.run(["cat", "/proc/self/status"], capture_output=True, text=True).stdout
        out["child_signals"] = {k: v.strip() for k, v in (ln.split(":", 1) for ln in status.splitlines())
                                if k in ("SigBlk", "SigIgn")}
    if out_dir is not None:
        out["out"] = []
        for rel, text in (item.get("write") or {}).items():
            p = Path(out_dir) / rel
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(text)
            out["out"].append(str(p))
    return out


def code_fingerprint() -> str:
    """A hash of this checkout's code and settings (the package's .py/.json/.xml/.yaml files and config/): equal
    on two machines when they run the same version. Read from disk at each call (about 10 ms): the driver's at
    the batch's start, a worker's as each run ends."""
    h = hashlib.sha256()
    pkg = ROOT / "src" / "robotatfactory"
    files = [p for base in (pkg, ROOT / "config") if base.is_dir() for p in base.rglob("*")
             if p.suffix in (".py", ".json", ".xml", ".yaml", ".yml") and "__pycache__" not in p.parts and p.is_file()]
    for p in sorted(files):
        h.update(p.relative_to(ROOT).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()[:16]
