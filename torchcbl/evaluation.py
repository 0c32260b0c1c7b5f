"""Small domain-free helpers the experiments share: summary statistics and provenance."""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import inspect
import json
import multiprocessing as mp
import os
import platform
import shutil
import signal
import sys
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from torchcbl._durable import write_durably
from torchcbl._progress import progress_bar
from torchcbl._text import one_line

__all__ = [
    "FigureError",
    "check_config_fields",
    "check_workers_start",
    "figure_style",
    "mean_sd",
    "paired_interval",
    "progress_bar",
    "run_versions",
    "save_whole",
    "worker_pool",
]

T = TypeVar("T")


# matplotlib's style is process-wide (rcParams): contexts entered in several threads at once
# would each restore what another set, and the caller's settings would be lost for good
_STYLE_LOCK = threading.RLock()


@contextlib.contextmanager
def figure_style() -> Iterator[None]:
    """Matplotlib's default style for the figures drawn and written inside: a run directory's
    PNGs and a rendered frame come out the same whatever the caller's rcParams,
    ``matplotlibrc`` or ``plt.style.use`` (a notebook's dark theme), and the caller's settings
    are back afterwards. The backend is left alone. matplotlib keeps its style for the whole
    process, so the blocks of several threads take turns. Only for what is finished inside
    the block (an RGB array, a PNG): a Figure handed back to a caller to draw on stays in the
    caller's style. Also a decorator: ``@figure_style()``."""
    import matplotlib.style

    with _STYLE_LOCK, matplotlib.style.context("default"):
        yield


def mean_sd(values: Iterable[float | None]) -> dict[str, float | int | None]:
    """Mean, sample standard deviation (ddof=1) and count of ``values``.

    None entries (e.g. a baseline that never learned) are left out and not counted; with no
    value left, mean and sd are None; with one value, sd is None (a spread needs two).
    """
    v = [float(x) for x in values if x is not None]
    if not v:
        return {"mean": None, "sd": None, "n": 0}
    return {
        "mean": float(np.mean(v)),
        "sd": float(np.std(v, ddof=1)) if len(v) > 1 else None,
        "n": len(v),
    }


_T975 = (
    12.706,
    4.303,
    3.182,
    2.776,
    2.571,
    2.447,
    2.365,
    2.306,
    2.262,
    2.228,
    2.201,
    2.179,
    2.160,
    2.145,
    2.131,
    2.120,
    2.110,
    2.101,
    2.093,
    2.086,
    2.080,
    2.074,
    2.069,
    2.064,
    2.060,
    2.056,
    2.052,
    2.048,
    2.045,
    2.042,
)  # Student t, 97.5 %, df = 1..30


def _t975(df: int) -> float:
    """Student t's 97.5 % quantile for ``df`` > 30 degrees of freedom: the Cornish-Fisher
    expansion about the normal's 1.959964 to 1/df^4 (Abramowitz & Stegun 26.7.5), within
    1e-5 of the exact value from df = 30 on (2.0423 at 30, 2.0211 at 40, 1.9799 at 120)."""
    z = 1.959963984540054
    g1 = (z**3 + z) / 4
    g2 = (5 * z**5 + 16 * z**3 + 3 * z) / 96
    g3 = (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / 384
    g4 = (79 * z**9 + 776 * z**7 + 1482 * z**5 - 1920 * z**3 - 945 * z) / 92160
    return z + g1 / df + g2 / df**2 + g3 / df**3 + g4 / df**4


def paired_interval(diffs: Sequence[float]) -> dict[str, Any]:
    """Mean of paired differences and its 95 % t interval: ``{mean, sd, n, ci95: [lo, hi]}``.

    ``diffs``: one difference a pair (a seed's figure of one arm or strategy minus the other's,
    the same seed's). ``sd`` is the sample sd (ddof=1); the interval is the mean ± t(0.975,
    n − 1) · sd / √n. With one value there is no spread: ``sd`` and ``ci95`` are None (never
    NaN). The driving experiment's arm (a) − arm (b) and the benchmark's strategy −
    confident execution (``results.json``'s ``paired``) both come from here.

    Raises:
        ValueError: ``diffs`` is empty."""
    d = np.asarray(diffs, dtype=np.float64)
    if d.size == 0:
        raise ValueError("paired_interval needs at least one difference")
    m = float(d.mean())
    if d.size == 1:
        return {"mean": m, "sd": None, "n": 1, "ci95": None}
    sd = float(d.std(ddof=1))
    t = _T975[d.size - 2] if d.size - 1 <= len(_T975) else _t975(d.size - 1)
    half = float(t * sd / np.sqrt(d.size))
    return {"mean": m, "sd": sd, "n": int(d.size), "ci95": [m - half, m + half]}


_PACKAGES = ("torchcbl", "corridor", "sumo_scenarios")  # the code a run's figures come from


def _source_revision() -> str:
    """The git commit of the checkout torchcbl is imported from, ``"git SHA"`` (``" with
    uncommitted changes"`` added when tracked files differ from it or the packages hold files
    not yet added); ``"unknown (...)"`` for
    an installed copy or without git. Only the project's own checkout counts: a copy
    installed inside another repository (a virtual environment in a user's project) does not
    take that repository's commit."""
    import shutil
    import subprocess
    from pathlib import Path

    import torchcbl

    root = Path(torchcbl.__file__).resolve().parents[1]
    git = shutil.which("git")
    if git is None:
        return "unknown (no git)"

    def run(*args: str) -> subprocess.CompletedProcess[bytes] | None:
        # bytes: a diff or a file name need not be UTF-8 (a latin-1 comment, a file named
        # by another system), and decoding them as text raised UnicodeDecodeError
        try:
            return subprocess.run([git, "-C", str(root), *args], capture_output=True, timeout=30)
        except (OSError, subprocess.SubprocessError):
            return None

    def text(out: bytes) -> str:
        return out.decode("utf-8", errors="replace").strip()

    top = run("rev-parse", "--show-toplevel")
    if top is None:
        return "unknown (git failed)"
    if top.returncode:  # not a repository, or one git refuses (another owner's, say)
        why = " ".join(text(top.stderr).split()[:12]) or "git failed"
        return (
            "unknown (not a git checkout)" if "not a git repository" in why else f"unknown ({why})"
        )
    if Path(os.fsdecode(top.stdout.strip())).resolve() != root:
        return "unknown (not a git checkout)"
    head = run("rev-parse", "HEAD")
    # --no-optional-locks: no index.lock taken to refresh the index (a user's own git commit
    # at that moment would fail on it)
    changed = run("--no-optional-locks", "status", "--porcelain", "--untracked-files=no")
    # files not yet added in the packages (a new module an edit imports) are code too; notes
    # or scratch files elsewhere in the checkout are not
    new = run("ls-files", "--others", "--exclude-standard", "-z", "--", *_PACKAGES)
    if head is None or head.returncode or changed is None or changed.returncode:
        return "unknown (git failed)"
    if new is None or new.returncode:
        return "unknown (git failed)"
    sha = text(head.stdout)
    untracked = sorted(p for p in new.stdout.split(b"\0") if p)
    if not changed.stdout.strip() and not untracked:
        return f"git {sha}"
    # which uncommitted changes: two different edits of the same commit are two codes
    diff = run("--no-optional-locks", "diff", "HEAD")
    if diff is None or diff.returncode:
        return f"git {sha} with uncommitted changes"
    h = hashlib.sha256(diff.stdout)
    for path in untracked:
        h.update(b"\0" + path + b"\0" + _file_digest(os.path.join(os.fsencode(root), path)))
    return f"git {sha} with uncommitted changes (diff {h.hexdigest()[:12]})"


def _file_digest(path: bytes) -> bytes:
    """SHA-256 of what an untracked ``path`` is: a file's contents (read in blocks), a
    symbolic link's target (not followed: it may dangle, or name a device), or only its kind
    (a directory, such as a repository nested in a package, which git lists as ``dir/``)."""
    import stat

    try:
        st = os.lstat(path)
        if stat.S_ISLNK(st.st_mode):
            return hashlib.sha256(b"link\0" + os.readlink(path)).digest()
        if not stat.S_ISREG(st.st_mode):
            return hashlib.sha256(b"not a file").digest()
        h = hashlib.sha256(b"file\0")
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
        return h.digest()
    except OSError:  # gone meanwhile, or unreadable
        return hashlib.sha256(b"unreadable").digest()


def run_versions(**extra: str) -> dict[str, str]:
    """Versions of Python and the core's dependencies, plus ``extra`` (a domain's simulator),
    for a results.json to say what produced it. ``torchcbl_source`` names the commit of the
    git checkout that ran, ``"git SHA"`` (plus ``" with uncommitted changes"`` when tracked
    files differed from it or the packages held files not yet added to git), or
    ``"unknown (...)"`` for an installed copy: the package's version stays the same across
    commits whose figures differ."""
    import gymnasium
    import torch

    import torchcbl

    return {
        "python": platform.python_version(),
        "torchcbl": torchcbl.__version__,
        "torchcbl_source": _source_revision(),
        "torch": torch.__version__,
        "numpy": np.__version__,
        "gymnasium": gymnasium.__version__,
        **extra,
    }


def _worker_start(parent: int | None = None) -> None:
    """Run in each worker of :func:`worker_pool` as it starts: its tqdm bars (the teaching
    loop's, hidden in a worker) take a thread lock instead of the multiprocessing lock tqdm
    makes by default, a named semaphore that a worker terminated after a Ctrl-C never
    releases; the resource tracker then printed a "leaked semaphore objects" warning under
    the command's one line. And it dies with ``parent`` (:func:`die_with_parent`). A worker
    forked while the pool held Ctrl-C takes it as the parent did before (:func:`_ctrl_c_held`)."""
    import threading

    from tqdm import tqdm

    _undo_ctrl_c_hold()
    tqdm.set_lock(threading.RLock())
    die_with_parent(parent)


def die_with_parent(parent: int | None) -> None:
    """End this worker process once ``parent`` (the process that started it, a pool's or an
    experiment's main process) is gone. Killed outright (SIGKILL: ``kill -9``, the
    out-of-memory killer; or SIGTERM, SIGHUP, which end Python without its cleanup) a main
    process cannot stop its workers: a pool's waited for ever on a queue nobody would write
    to again, an experiment's ran its seed to the end, writing into a seed directory that a
    resumed run clears and runs again. A daemon thread polls every 0.5 s: as this process's
    parent (spawn, fork), else, when another process started this one (a forkserver
    context), by its pid. None: nothing is watched. (The kernel's parent-death signal would
    also fire when the parent's *thread* that started this process ends, while the parent
    lives on.)"""
    import threading

    if parent is not None:
        threading.Thread(
            target=_exit_when_orphaned, args=(parent,), name="torchcbl-parent-watch", daemon=True
        ).start()


def _exit_when_orphaned(parent: int, every: float = 0.5) -> None:
    """Exit at once when the process ``parent`` is gone (see :func:`die_with_parent`)."""
    import time

    direct = os.getppid() == parent
    while True:
        if direct:
            gone = os.getppid() != parent
        else:
            gone = not _alive(parent)
        if gone:
            os._exit(1)
        time.sleep(every)


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs: there, and not a zombie (a killed process its parent has
    not yet reaped answers signal 0 as if alive)."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except FileNotFoundError:
        return False
    except OSError:  # no /proc (macOS): signal 0 asks whether it is there, and sends nothing
        pass
    if os.name == "nt":  # signal 0 is CTRL_C_EVENT there
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # there, but not ours to signal
        return True
    return True


def check_workers_start(context: Any = None) -> None:
    """Start one process of the multiprocessing ``context`` (None: the default) that does
    nothing, and raise if it does not end cleanly, before a run starts its worker processes.

    A spawned process first re-imports the program's main module; a script that starts a run
    at its top level, outside ``if __name__ == "__main__":``, makes every worker start that
    run again there, and fail at start-up (exit code 1). A ``multiprocessing.Pool`` replaces
    such workers for ever (the run hangs, printing their tracebacks), and a process pool
    executor reports a worker that died abruptly.

    Raises:
        RuntimeError: the process exited with a nonzero code or was killed; the message
            names the main module and the guard. (The process's own traceback, if any, is
            on stderr above it.)
    """
    ctx = context if context is not None else mp.get_context()
    probe = ctx.Process(target=int, name="torchcbl-start-check")  # int(): does nothing
    try:
        with _ctrl_c_held():  # a probe started is joined (or stopped) before a Ctrl-C acts
            probe.start()
        probe.join()
        code = probe.exitcode
    finally:
        if probe.is_alive():  # a Ctrl-C as it started or during the join
            probe.terminate()
            probe.join()
        if not probe.is_alive():  # its pipes closed now, not when a kept traceback goes
            probe.close()
    if code == 0:
        return
    how = (
        f"was killed by signal {-code}"
        if code is not None and code < 0
        else f"exited with code {code}"
    )
    main = getattr(sys.modules.get("__main__"), "__file__", None)
    raise RuntimeError(
        f"worker processes cannot start: a new process, which first re-imports this program's "
        f"main module ({main or 'its __main__'}), {how} before it could run anything (its "
        "traceback, if any, is above). A script that starts a run with worker processes must "
        'start it under `if __name__ == "__main__":`, or each worker runs the script\'s '
        "top-level code again as it starts and fails; put the call under that guard (or fix "
        "what the traceback shows)"
    )


def _how_a_worker_died(broken: BaseException, exitcodes: Iterable[int | None]) -> str:
    """How a pool broke: a result or exception a worker sent back that cannot be unpickled
    (the pool's error then has the reading's traceback as its cause), else how the dead worker
    ended, from the processes' exit codes after the pool terminated the others (SIGTERM): the
    first other code, else SIGTERM itself."""
    if broken.__cause__ is not None:
        return (
            "sent back a result or an exception that cannot be unpickled here (the traceback "
            "above shows the reading)"
        )
    codes = [c for c in exitcodes if c is not None]
    dead = [c for c in codes if c != -signal.SIGTERM] or [c for c in codes if c != 0]
    if not dead:
        return "died abruptly"
    code = dead[0]
    if code >= 0:
        return (
            f"exited with code {code} in the middle of a task (os._exit, or native code "
            "that ended the process)"
        )
    try:
        name = signal.Signals(-code).name
    except ValueError:
        name = f"signal {-code}"
    why = " (the out-of-memory killer sends it)" if code == -signal.SIGKILL else ""
    return f"was killed by {name}{why}"


@contextlib.contextmanager
def _ctrl_c_held() -> Iterator[None]:
    """Hold a Ctrl-C (SIGINT) that comes while the block runs in the main thread, and act on
    it as the handler in place would (KeyboardInterrupt, by default) once the block has ended.

    A worker process is started, then kept by the pool: a KeyboardInterrupt in between left
    a process nobody terminated (it ran on as long as the main process did, or died printing
    a traceback). A second Ctrl-C is not held (a start that hangs can still be stopped).
    Elsewhere (another thread, a SIGINT ignored or left to the system) the block runs as it
    is."""
    old = signal.getsignal(signal.SIGINT)
    if threading.current_thread() is not threading.main_thread() or not callable(old):
        yield
        return
    held: list[Any] = []

    def hold(signum: int, frame: Any) -> None:
        if held:
            held.clear()
            old(signum, frame)
        else:
            held.append(frame)

    hold._before_hold = old  # type: ignore[attr-defined]  # for _undo_ctrl_c_hold
    signal.signal(signal.SIGINT, hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)
        if held:
            old(signal.SIGINT, held[0])


def _undo_ctrl_c_hold() -> None:
    """In a process forked inside :func:`_ctrl_c_held` (its parent's block), put back the
    SIGINT handler that was in place before the hold. A fork child copies the holding handler
    and never leaves the block, so it swallowed its first Ctrl-C. Elsewhere it does nothing."""
    if threading.current_thread() is not threading.main_thread():
        return
    handler = signal.getsignal(signal.SIGINT)
    while hasattr(handler, "_before_hold"):  # a hold inside a hold holds the outer one
        handler = handler._before_hold
    if handler is not signal.getsignal(signal.SIGINT):
        signal.signal(signal.SIGINT, handler)


class _RecordingPool(ProcessPoolExecutor):
    """A process pool that keeps every worker process it started (``started``), so that the
    exit code of one that died stays at hand whatever the pool's own bookkeeping dropped.
    (A CI run that named SIGTERM for a SIGKILLed worker had another cause: the pool's own
    thread reaping it; see :func:`worker_pool`.)"""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.started: list[Any] = []
        super().__init__(*args, **kwargs)

    def _spawn_process(self) -> None:  # CPython's hook for each worker it starts
        with _ctrl_c_held():  # a worker started is kept before a Ctrl-C stops the pool
            before = set((self._processes or {}).keys())  # type: ignore[attr-defined]
            super()._spawn_process()  # type: ignore[misc]
            for pid, proc in (self._processes or {}).items():  # type: ignore[attr-defined]
                if pid not in before:
                    self.started.append(proc)

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        """As the executor's, except that a pool a worker's death broke while this call ran
        raises BrokenProcessPool, as it does once broken. (CPython looks at the pool, then
        starts a worker if one is missing; a pool broken in between has closed the call queue
        that worker is started with, and the start raised a bare "OSError: handle is
        closed".)"""
        try:
            return super().submit(fn, *args, **kwargs)
        except OSError:
            broken = getattr(self, "_broken", False)  # CPython's mark of a broken pool
            if not broken:
                raise
            raise BrokenProcessPool(broken) from None


@contextlib.contextmanager
def worker_pool(
    workers: int,
    context: Any = None,
    *,
    running: str = "one of its tasks",
    after: str = "run it again (with fewer workers if memory ran out)",
) -> Iterator[ProcessPoolExecutor]:
    """A :class:`~concurrent.futures.ProcessPoolExecutor` of ``workers`` processes (started by
    the multiprocessing ``context``) that stops its workers at once when the block raises.

    A worker that dies in the middle of a task (the out-of-memory killer) breaks the pool, as
    does a result or exception it sends back that cannot be unpickled: the
    ``BrokenProcessPool`` the block raises (from a future, or from ``submit`` while the block
    still submits tasks) becomes a RuntimeError saying which, and how the worker died (its
    signal or exit code), while it ran ``running``, then ``after`` (what to do).

    The executor's own ``with`` waits for the running tasks on any exit: after a Ctrl-C that
    reached this process alone (``kill -INT``), a run went on computing seeds nobody would
    read, and a second Ctrl-C during that wait left the interpreter hanging at exit. Here an
    exception (KeyboardInterrupt included) cancels the queued tasks, terminates the workers
    and is re-raised; a block that ends normally waits for its tasks as usual.

    First :func:`check_workers_start` starts one process of ``context``: a worker that fails
    at start-up (a script without ``if __name__ == "__main__":``) raises its RuntimeError,
    which names the guard, instead of breaking the pool (a BrokenProcessPool that reads like
    a worker killed mid-task).
    """
    check_workers_start(context)
    pool = _RecordingPool(
        max_workers=workers,
        mp_context=context,
        initializer=_worker_start,
        initargs=(os.getpid(),),
    )
    try:
        yield pool
    except BaseException as exc:
        processes = list(pool.started) or list((getattr(pool, "_processes", None) or {}).values())
        manager = getattr(pool, "_executor_manager_thread", None)  # shutdown() forgets it
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in processes:
            if proc.is_alive():
                proc.terminate()
        for proc in processes:
            proc.join(timeout=10)
        # the pool's own thread, seeing it broken, terminates and joins the workers too: a
        # process it reaped read here as "no such child", no exit code, until that thread
        # kept the code (a CI run named SIGTERM for a SIGKILLed worker); once it has ended,
        # every code is kept
        if manager is not None and manager is not threading.current_thread():
            manager.join(timeout=10)
        if isinstance(exc, BrokenProcessPool):
            how = _how_a_worker_died(exc, (proc.exitcode for proc in processes))
            raise RuntimeError(f"a worker process {how} while it ran {running}; {after}") from exc
        raise
    pool.shutdown(wait=True)


# ---------------------------------------------------------------------------- resuming a run

#: The file in a seed's directory that holds its finished result and the config it was run
#: with (written atomically when the seed ends; a seed directory without it did not finish).
SEED_RESULT = "seed_result.json"


class ResumeError(ValueError):
    """A run directory that a resume refuses: ``core`` says why (what differs), the message
    adds what to do."""

    def __init__(self, core: str, remedy: str, kind: str = "settings") -> None:
        super().__init__(f"{core}; {remedy}")
        self.core = core
        self.remedy = remedy
        self.kind = kind
        """What differs: ``"settings"`` (the config), ``"seeds"`` (seeds this config does not
        run) or ``"code"`` (the versions of the code that computed a finished seed)."""


def plain_json(value: Any, default: Any = None) -> Any:
    """``value`` as JSON gives it back (tuples as lists, numpy scalars as numbers, ...):
    what a result read back from its file holds."""
    return json.loads(json.dumps(value, default=default))


def write_seed_result(
    seed_dir: Any,
    config: dict[str, Any],
    result: dict[str, Any],
    default: Any = None,
    versions: dict[str, str] | None = None,
) -> dict[str, Any]:
    """Write ``result``, the run's ``config`` (JSON form) and the ``versions`` of the code that
    computed it (:func:`run_versions`) into ``seed_dir/seed_result.json`` atomically (a
    temporary file renamed over it: a run killed while writing leaves no result), and return
    the result as it reads back from the file."""
    path = Path(seed_dir) / SEED_RESULT
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps({"config": config, "result": result, "versions": versions}, default=default)
    write_atomically(path, text)
    return json.loads(text)["result"]


def write_atomically(path: Any, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file renamed over it, fsynced
    before the rename and its directory after: a reader (a resume) finds the whole file or
    none, after a power cut too."""
    path = Path(path)
    write_durably(path, text.encode("utf-8"), path.with_name(path.name + ".tmp"))


def save_whole(path: str | os.PathLike[str], save: Callable[..., Any], **kwargs: Any) -> Path:
    """Write the file ``save(path, **kwargs)`` writes (``Figure.savefig``,
    ``matplotlib.image.imsave``), whole or not at all: ``save`` writes into memory, in the
    format ``path``'s extension names (as it would for the path itself, unless ``format`` is
    given), and the bytes go to a temporary file in the same folder that is fsynced and renamed
    over ``path``. A run killed (or a disk filled) mid-write leaves the earlier file as it was,
    never a truncated one under the name; the bytes are those ``save`` writes to the path.

    Returns ``path`` as a :class:`~pathlib.Path`. An error of ``save`` or of the write is
    raised as it is, with no temporary file left behind.
    """
    import io

    path = Path(path)
    if "format" not in kwargs and path.suffix:
        kwargs["format"] = path.suffix[1:].lower()  # "map.PNG" as savefig writes it
    buf = io.BytesIO()
    save(buf, **kwargs)
    write_durably(path, buf.getvalue(), path.with_name(f".{path.name}.{os.getpid()}.tmp"))
    return path


def _short(value: Any, width: int = 60) -> str:
    """``value`` for a one-line message: a run of whole numbers as ``[0, ..., 29]``, else its
    repr cut at ``width`` characters."""
    run = isinstance(value, list) and len(value) > 3
    if run and all(type(v) is int for v in value) and value == list(range(value[0], value[-1] + 1)):
        return f"[{value[0]}, ..., {value[-1]}]"
    text = repr(value)
    return text if len(text) <= width else text[: width - 3] + "..."


def config_differences(stored: Any, wanted: Any, prefix: str = "") -> list[str]:
    """The settings in which ``stored`` (a config's JSON form, as a file holds it) differs
    from ``wanted`` (the same form): ``"name (X there, Y here)"``, nested fields dotted."""
    if isinstance(stored, dict) and isinstance(wanted, dict):
        out: list[str] = []
        for key in [*stored, *(k for k in wanted if k not in stored)]:
            name = f"{prefix}{key}"
            if key not in wanted:
                out.append(f"{name} (set there, not known here)")
            elif key not in stored:
                out.append(f"{name} (not set there, {_short(wanted[key])} here)")
            else:
                out += config_differences(stored[key], wanted[key], f"{name}.")
        return out
    if stored == wanted:
        return []
    return [f"{prefix.rstrip('.') or 'config'} ({_short(stored)} there, {_short(wanted)} here)"]


def check_config_fields(cls: type, data: Any) -> dict[str, Any]:
    """``data``, an experiment config's stored form (``results.json``'s ``"config"``), as a
    new dict, once it is a dict of the fields of ``cls`` (a dataclass): what an experiment
    config's ``from_dict`` checks before it builds ``cls``.

    Raises:
        ValueError: ``data`` is not a mapping, is a whole ``results.json`` (its ``"config"``
            is wanted), or names a field ``cls`` lacks.
    """
    name = cls.__name__
    if not isinstance(data, Mapping):
        raise ValueError(
            f"expected a dict of {name}'s fields (results.json's 'config'), got "
            f"{type(data).__name__}"
        )
    if "config" in data and "per_seed" in data:
        raise ValueError(
            f"expected a dict of {name}'s fields, got a whole results.json; "
            'pass its "config": from_dict(results["config"])'
        )
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ValueError(f"unknown {name} fields {unknown}; its fields: {sorted(names)}")
    return dict(data)


def finished_seeds(
    run_dir: Any,
    seed_dirs: dict[int, Any],
    config: dict[str, Any],
    strays: list[Any],
    remedy: str,
    versions: dict[str, str] | None = None,
) -> dict[int, dict[str, Any]]:
    """What a resume of ``run_dir`` takes: the finished result of each seed of ``seed_dirs``
    (seed -> its directory) whose ``seed_result.json`` was run with ``config`` (the run's
    config in its JSON form) and, where ``versions`` is given, by the code of those versions
    (:func:`run_versions`: the commit, torch, the simulator, ...). Reads only; a seed directory
    without a readable result is one the resume clears and runs again.

    Raises:
        FileExistsError: ``run_dir`` holds results.json (its run finished).
        ResumeError: a finished seed was run with another config or by other code (the
            message names what differs), or ``strays`` (seed directories of seeds this config
            does not run) is not empty. ``remedy`` ends the message.
    """
    run_dir = Path(run_dir)
    if (run_dir / "results.json").exists():
        raise FileExistsError(
            f"{run_dir} already holds results.json: its run finished, there is nothing to "
            "resume; choose a new run_dir"
        )
    if strays:
        names = ", ".join(str(Path(p).relative_to(run_dir)) for p in strays)
        raise ResumeError(
            f"{run_dir} holds seeds that this config does not run ({names}): it was started "
            "with other seeds",
            remedy,
            "seeds",
        )
    wanted = plain_json(config)
    done: dict[int, dict[str, Any]] = {}
    for seed, seed_dir in seed_dirs.items():
        stored = _read_seed_result(Path(seed_dir))
        if stored is None:
            continue
        differ = config_differences(stored["config"], wanted)
        if differ:
            raise ResumeError(
                f"seed {seed}'s finished result in {Path(seed_dir) / SEED_RESULT} was run with "
                f"other settings: {'; '.join(differ)}",
                remedy,
            )
        kept = stored.get("versions")
        if versions is not None and kept != plain_json(versions):
            what = (
                "; ".join(config_differences(kept, plain_json(versions)))
                if isinstance(kept, dict)
                else "its versions are not recorded"
            )
            raise ResumeError(
                f"seed {seed}'s finished result in {Path(seed_dir) / SEED_RESULT} was computed "
                f"by other code: {what} (seeds of two versions would be mixed in one result)",
                "resume with the code it was started with, or choose a new run_dir",
                "code",
            )
        done[seed] = stored["result"]
    return done


def _read_seed_result(seed_dir: Any) -> dict[str, Any] | None:
    """A seed directory's ``{"config", "result"}``, or None where it holds no readable one."""
    try:
        data = json.loads((seed_dir / SEED_RESULT).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or not {"config", "result"} <= set(data):
        return None
    return data


class RunDirLockedError(RuntimeError):
    """Another process is running an experiment into the same run directory."""


class FigureError(RuntimeError):
    """A finished run's figures could not be drawn; its results are kept.

    An experiment's ``run_experiment`` writes ``results.json`` (and its summary) before it
    draws the figures, so a figure that fails (matplotlib missing, a full disk) loses no
    computed result: it raises this, the figure's own exception as ``__cause__``, with
    ``run_dir`` holding the results. The domain's ``plot_results(results, run_dir)``,
    ``torchcbl plot RUN_DIR`` or ``torchcbl reproduce --resume`` draws the figures again from
    them.
    """

    def __init__(self, message: str, run_dir: str | os.PathLike[str]) -> None:
        super().__init__(message)
        self.run_dir = Path(run_dir)
        """The run directory: its results.json is written."""

    @classmethod
    def of(
        cls,
        domain: str,
        run_dir: str | os.PathLike[str],
        cause: BaseException,
        *,
        then: str | None = None,
    ) -> FigureError:
        """The error for ``domain``'s figures failing on ``cause`` in ``run_dir``: it names
        the cause, where the results are and what to do once the cause is fixed: ``then``
        (e.g. ``torchcbl reproduce``'s "finish the run with ..."), by default the command that
        draws the figures (``torchcbl plot RUN_DIR``)."""
        import shlex

        run_dir = Path(run_dir)
        text = one_line(cause)
        then = then or f"draw the figures with torchcbl plot {shlex.quote(str(run_dir))}"
        return cls(
            f"the {domain} figures could not be drawn into {run_dir} ({type(cause).__name__}: "
            f"{text}); its results are kept in {run_dir / 'results.json'}: once that is "
            f"fixed, {then}",
            run_dir,
        )

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (str(self), self.run_dir))


@contextlib.contextmanager
def hold_run_dir(run_dir: Any) -> Iterator[None]:
    """Hold ``run_dir`` (made if missing) for one experiment run: an ``fcntl.flock`` on its
    ``.run.lock`` (released by the kernel when the process dies, SIGKILL included). A second
    run into it, a resume from another shell while the first survives under nohup or tmux
    say, would clear and rewrite the seed directories the first is writing:
    :class:`RunDirLockedError`, naming the holder's pid. Where flock is missing, nothing."""
    run_dir = Path(run_dir)
    try:
        import fcntl
    except ImportError:  # not a POSIX system
        yield
        return
    made = [p for p in (run_dir, *run_dir.parents) if not p.exists()]
    run_dir.mkdir(parents=True, exist_ok=True)
    lock = run_dir / ".run.lock"
    with open(lock, "a+", encoding="utf-8") as f:
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.seek(0)
            holder = f.read().strip() or "unknown"
            raise RunDirLockedError(
                f"{run_dir} is being written by another run (pid {holder}, which holds "
                f"{lock}); wait for it to end, or stop it, then run again (with --resume / "
                "resume=True to go on from its finished seeds)"
            ) from None
        try:
            # straight to the file, not through f's buffer: a pid that does not fit (a full
            # disk) would stay buffered and make closing the lock raise a bare OSError in
            # place of the error the run meets at its first real write, which names the file
            os.ftruncate(f.fileno(), 0)
            os.write(f.fileno(), str(os.getpid()).encode())
        except OSError:
            pass  # the lock holds without the pid
        try:
            yield
        except BaseException:
            # a run refused (or stopped) before it wrote anything leaves no trace: the
            # directories made here for the lock go again (while it is still held)
            if made and [p.name for p in run_dir.iterdir()] == [lock.name]:
                lock.unlink()
                for p in made:
                    with contextlib.suppress(OSError):
                        p.rmdir()
            raise


def holding_run_dir(run: Callable[..., T]) -> Callable[..., T]:
    """Decorate an experiment's ``run_experiment(config, run_dir, ...)``: each call holds its
    ``run_dir`` (:func:`hold_run_dir`) while it runs."""
    signature = inspect.signature(run)

    @functools.wraps(run)
    def held(*args: Any, **kwargs: Any) -> T:
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        with hold_run_dir(bound.arguments["run_dir"]):
            return run(*args, **kwargs)

    return held


def clear_unfinished(seed_dirs: dict[int, Any], finished: Iterable[int]) -> None:
    """Remove the directory of each seed of ``seed_dirs`` (seed -> directory) not in
    ``finished``: a seed stopped part-way is run again from scratch."""
    done = set(finished)
    for seed, seed_dir in seed_dirs.items():
        if seed not in done and Path(seed_dir).exists():
            shutil.rmtree(seed_dir)
