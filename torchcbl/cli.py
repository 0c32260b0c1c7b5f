"""The ``torchcbl`` command line.

This is the only core module that reaches the domains (``corridor``, ``sumo_scenarios``), and it
imports them lazily, inside the command that needs them, so ``torchcbl --help`` stays fast and the
core never depends on a simulator.

Commands (the options in full: README.md's command block, which a test holds to ``--help``)::

    torchcbl --version
    torchcbl reproduce [corridor|driving|all] [--full] [--seeds N] [--workers N] [--out DIR]
                       [--resume]
    torchcbl evaluate SESSION_DIR [--domain corridor|driving] [--steps N] [--seed S] ...
    torchcbl replay EPISODES.json|SESSION_DIR [--list] [--episode N | --label TEXT] [--gif OUT] ...
    torchcbl plot RUN_DIR
    torchcbl show SESSION_DIR|DIR [--json]
    torchcbl teach corridor|driving [--run-dir DIR] [--resume] [--seed S] [--steps N] ...
    torchcbl benchmark [--quick] [--strategies S,..] [--envs E,..] [--seeds N] [--ray] ...
"""

from __future__ import annotations

import argparse
import codecs
import dataclasses
import importlib.util
import json
import os
import re
import shlex
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

from torchcbl._checkpoints import DEFAULT_KEEP_CHECKPOINTS, is_keep_count
from torchcbl._text import counted as _counted
from torchcbl._text import one_line as _one_line

_DOMAINS = {
    "corridor": "corridor.experiment",
    "driving": "sumo_scenarios.experiment",
}

# How a teaching session's config.json tells its domain: the gymnasium id the env was made
# with (``torchcbl teach``), else its observation space and action count (the experiments
# build their envs directly, without an id), so that a user's own env of the same shape is not
# taken for a domain's. tests/test_cli.py checks both against the envs.
_ENV_IDS = {"torchcbl/Corridor-v0": "corridor", "torchcbl/Driving-v0": "driving"}
_SPACES = {  # (n_features, n_actions, repr of the observation space) -> domain
    (3, 4, "Box(0.0, 1.5, (3,), float32)"): "corridor",
    (4, 3, "Box([-25. -25. -25.   0.], [25. 25. 25.  4.], (4,), float32)"): "driving",
}

_SESSION_HINT = (
    "expected a teaching session directory (one holding config.json, e.g. "
    "runs/reproduce/corridor/sessions/seed0, or the --run-dir of torchcbl teach)"
)
_EPISODES_HINT = (
    "expected an episodes.json written by the driving experiment "
    "(runs/reproduce/driving/seed_<k>/episodes.json) or a driving teaching session's directory "
    "(torchcbl teach driving --run-dir)"
)


# torchcbl's declared dependencies, by the top-level module a ModuleNotFoundError names: the
# requirement pyproject.toml pins (tests/test_cli.py checks the two agree) and what needs it (a
# missing one is one line, exit code 2, as --ray says of a missing Ray)
_DEPENDENCIES = {
    "libsumo": ("libsumo>=1.22", "the driving domain (SUMO, run through libsumo)"),
    "sumolib": ("sumolib>=1.22", "the driving domain (SUMO's network files, read with sumolib)"),
    "sumo": ("eclipse-sumo>=1.22", "the driving domain (SUMO itself, eclipse-sumo)"),
    "pymunk": ("pymunk>=7.0", "the corridor domain (its physics)"),
    "gymnasium": ("gymnasium>=0.29", "the environments and the teaching loop"),
    "matplotlib": ("matplotlib>=3.7", "the figures and the replay's GIF"),
    "imageio": ("imageio>=2.30", "the replay's GIF"),
    "torch": ("torch>=2.2", "the model (the Gaussian mixtures)"),
    "numpy": ("numpy>=1.24", "torchcbl"),
    "tqdm": ("tqdm>=4.60", "the progress bars"),
}
# SUMO's three wheels, installed together (of one version)
_SUMO_MODULES = ("libsumo", "sumo", "sumolib")
# what each domain needs; a command adds what it needs besides (the figures, the replay's GIF).
# What a command reaches only as it goes, after work that a missing one would throw away, is
# checked before it starts (reproduce's figures come after every seed, its driving part after
# the corridor's; a benchmark's driving cells after others, its plot after every cell)
_DOMAIN_NEEDS = {"corridor": ("pymunk",), "driving": ("libsumo", "sumolib")}


def _install_command(module: str) -> str:
    """The pip command that installs the dependency imported as ``module``, as pinned."""
    modules = _SUMO_MODULES if module in _SUMO_MODULES else (module,)
    return "pip install " + " ".join(f"'{_DEPENDENCIES[m][0]}'" for m in modules)


class _UsageError(Exception):
    """A mistake in what the user asked for: reported as one line, exit code 2."""


def _missing_dependency(exc: BaseException | None) -> str | None:
    """The one line for a ModuleNotFoundError of one of torchcbl's dependencies (``exc``, or
    the exception that caused it: a failed cell's or figure's): the package, what needs it and
    how to install it; None for any other error."""
    while exc is not None:
        if isinstance(exc, ModuleNotFoundError) and exc.name:
            top = exc.name.partition(".")[0]
            if top in _DEPENDENCIES:
                feature = _DEPENDENCIES[top][1]
                return (
                    f"{top} is missing ({_one_line(exc)}): {feature} needs it; install it into "
                    f"this environment with `{_install_command(top)}` (from a checkout, "
                    "`bash scripts/setup.sh` installs every dependency)"
                )
        exc = exc.__cause__
    return None


def _check_importable(modules: Sequence[str]) -> None:
    """A one-line error, before anything runs, unless each of ``modules`` imports."""
    for name in dict.fromkeys(modules):
        try:
            importlib.import_module(name)
        except ImportError as exc:
            line = _missing_dependency(exc) or f"{name} cannot be imported ({_one_line(exc)})"
            raise _UsageError(line) from None


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage mistake is one line (no usage block), exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}; see {self.prog} --help\n")


def _int_at_least(
    minimum: int, below: int | None = None, hint: str = "", at_most: int | None = None
) -> Any:
    """An argparse type: a whole number >= ``minimum`` (and < ``below``, and <= ``at_most``),
    else a one-line usage error (ending in `` (hint)`` where ``hint`` is given)."""
    if at_most is not None:
        below = at_most + 1

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum or (below is not None and value >= below):
            expected = (
                f"from {minimum} to {at_most}"
                if at_most is not None
                else f">= {minimum}" + ("" if below is None else f" and < {below}")
            )
            raise argparse.ArgumentTypeError(
                f"expected a whole number {expected}, got {text!r}" + (f" ({hint})" if hint else "")
            ) from None
        return value

    return parse


_positive_int = _int_at_least(1)

# The most seeds `torchcbl benchmark --seeds` and `torchcbl reproduce --seeds` take: each seed
# is a cell of every strategy and env (10,000 seeds of the shipped 6 strategies x 2 envs:
# 120,000 cells, about 0.2 GB of cell configurations before the first runs). A count far above
# it, a slip of the keyboard, made a list of that many seeds and ended in a bare MemoryError.
_MAX_SEEDS = 10_000


def _budgets(text: str) -> tuple[int, ...]:
    """An argparse type: label budgets as comma-separated whole numbers >= 1."""
    try:
        values = tuple(int(b) for b in text.split(","))
    except ValueError:
        values = ()
    if not values or min(values) < 1 or list(values) != sorted(set(values)):
        raise argparse.ArgumentTypeError(
            f"expected increasing comma-separated whole numbers >= 1 (e.g. 10,20,40), got {text!r}"
        )
    return values


def _keep_checkpoints(text: str) -> int | str:
    """An argparse type: ``--keep-checkpoints N|all``, a whole number >= 1 (the newest
    checkpoints kept) or ``all`` (every one), else a one-line usage error. ``all`` is returned
    as the string: the option's absence (None) is another choice (a resume's "as before")."""
    if text.strip().lower() == "all":
        return "all"
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not is_keep_count(value):
        raise argparse.ArgumentTypeError(
            "expected a whole number >= 1 (the newest checkpoints kept, besides checkpoint 0) "
            f"or all (every one), got {text!r}"
        ) from None
    return value


def _kept(option: int | str | None, default: Any) -> Any:
    """What ``--keep-checkpoints`` gives ``keep_checkpoints=``: ``default`` where it was left
    out, None for ``all``, else the number."""
    return default if option is None else None if option == "all" else option


_nonnegative_int = _int_at_least(0)
_seed = _int_at_least(0, 2**32)  # a seed every seeded part takes (numpy, the GMM set, SUMO)


def _experiment_module(domain: str) -> Any:
    return importlib.import_module(_DOMAINS[domain])


def _experiment_config(domain: str, module: Any, args: argparse.Namespace) -> Any:
    config_cls = next(
        getattr(module, name)
        for name in dir(module)
        if name.endswith("ExperimentConfig") and isinstance(getattr(module, name), type)
    )
    try:
        config = config_cls.full() if args.full else config_cls()
        if args.seeds is not None:
            config = _replace_seeds(config, args.seeds)
    except ValueError as exc:
        raise _UsageError(f"the {domain} experiment refuses these settings: {exc}") from None
    return config


def _cmd_reproduce(args: argparse.Namespace) -> int:
    domains = list(_DOMAINS) if args.domain == "all" else [args.domain]
    # Every setting is checked before anything is written: a refused command leaves no trace.
    plan = []
    for domain in domains:
        module = _experiment_module(domain)
        plan.append((domain, module, _experiment_config(domain, module, args)))
    _check_importable([m for domain in domains for m in _DOMAIN_NEEDS[domain]] + ["matplotlib"])
    requested = _output_dir(Path(args.out), "--out")
    finished = _resume_plan(requested, plan) if args.resume else {}
    out = requested if args.resume else _fresh_dir(requested)
    summaries: list[str] = []
    # what a figure that fails says to do once its cause is fixed: go on with this command
    plus = "" if args.resume else f" plus --resume --out {_shell(out)}"
    go_on = f"finish the run with the same command{plus} (it draws them)"
    try:
        for domain, module, config in plan:
            run_dir = out / domain
            if domain in finished:
                print(f"== {domain}: finished before, taken from {run_dir}", flush=True)
                results = finished[domain]
                _draw_missing_figures(domain, module, run_dir, results)
                elapsed = results.get("seconds", 0.0)
                summary = module.format_summary(results)
                summaries.append(
                    f"## {domain} ({elapsed:.0f} s, run directory `{run_dir}`)\n\n{summary}"
                )
                print(summary, flush=True)
                continue
            how = "resumed" if args.resume else "run"
            print(
                f"== {domain}: {'full' if args.full else 'quick'} {how} into {run_dir}",
                flush=True,
            )
            t0 = time.perf_counter()
            from torchcbl.evaluation import FigureError, RunDirLockedError

            try:
                results = module.run_experiment(
                    config,
                    run_dir,
                    workers=args.workers,
                    progress=not args.no_progress,
                    resume=args.resume,
                )
            except RunDirLockedError as exc:
                raise _UsageError(f"--out {out}: {exc}") from None
            except FigureError as exc:  # its results are written: say how to go on
                cause = exc if exc.__cause__ is None else exc.__cause__
                raise FigureError.of(domain, exc.run_dir, cause, then=go_on) from cause
            elapsed = time.perf_counter() - t0
            summary = module.format_summary(results)
            summaries.append(
                f"## {domain} ({elapsed:.0f} s, run directory `{run_dir}`)\n\n{summary}"
            )
            print(summary, flush=True)
    except BaseException as exc:
        if not args.resume and out.is_dir() and not any(out.iterdir()):
            out.rmdir()  # nothing was written: leave nothing behind (a resumed one is kept)
        elif isinstance(exc, KeyboardInterrupt):  # main says it in its one line
            exc.note = (  # type: ignore[attr-defined]
                f" (its finished seeds are kept: go on with the same command{plus})"
            )
        raise
    text = "\n\n".join(summaries) + "\n"
    from torchcbl.evaluation import write_atomically

    write_atomically(out / "summary.md", text)  # whole or not at all: it marks a finished run
    print(f"\nSummary written to {out / 'summary.md'}")
    return 0


def _draw_missing_figures(domain: str, module: Any, run_dir: Path, results: dict[str, Any]) -> None:
    """Draw again the figures (``module.FIGURES``) missing from the run directory of a domain
    that finished before (its results.json written, a figure that failed after it, or one
    deleted), saying so in one line; those there are not written (``plot_results``'s
    ``only``). Where they cannot be drawn (the cause not fixed yet, the sessions they read
    gone), one line on stderr says so and how to draw them later, and the run goes on: its
    results are whole without them."""
    missing = [name for name in module.FIGURES if not (run_dir / name).is_file()]
    if not missing:
        return
    print(
        f"== {domain}: {', '.join(missing)} missing in {run_dir}, drawn again from its results",
        flush=True,
    )
    try:
        module.plot_results(results, run_dir, only=missing)
    except Exception as exc:  # noqa: BLE001 (any figure's failure: said in one line)
        print(
            f"torchcbl reproduce: warning: {domain}: {', '.join(missing)} could not be drawn "
            f"again ({type(exc).__name__}: {_one_line(exc)}); the run goes on without them: "
            f"draw them with `torchcbl plot {_shell(run_dir)}` once that is fixed",
            file=sys.stderr,
            flush=True,
        )


def _resume_plan(out: Path, plan: list[tuple[str, Any, Any]]) -> dict[str, Any]:
    """What ``reproduce --resume`` takes from ``out``, checked before anything is written: the
    results of each domain that finished (its results.json, run with these settings), by
    domain. A run stopped part-way is refused (one line) where it was started otherwise: with
    other settings (--full, --seeds: the settings that differ are named) or other domains, or
    where it finished (its summary.md)."""
    from torchcbl.evaluation import ResumeError, config_differences, plain_json

    again = "give the settings it was started with (the same domain, --full and --seeds)"
    if not out.is_dir():
        raise _UsageError(
            f"--resume: {out} does not exist; expected the --out directory of a stopped "
            "torchcbl reproduce run (without --resume a new run starts there)"
        )
    if (out / "summary.md").is_file():
        raise _UsageError(
            f"--resume: {out} holds summary.md: its run finished, there is nothing to resume; "
            "without --resume a new run starts beside it"
        )
    wanted = {domain for domain, _, _ in plan}
    other = sorted(d for d in _DOMAINS if d not in wanted and (out / d).exists())
    if other:
        raise _UsageError(
            f"--resume: {out} holds a {' and a '.join(other)} run too, which this command does "
            f"not run: it was started as another torchcbl reproduce; {again}"
        )
    if any(out.iterdir()) and not any((out / d).exists() for d in wanted):
        names = " or ".join(f"{d}" for d in sorted(wanted))
        raise _UsageError(
            f"--resume: {out} holds no {names} directory of a torchcbl reproduce run; expected "
            "the --out directory of a stopped run (the one that holds "
            f"{' and '.join(f'{d}/' for d in sorted(wanted))}), or an empty one"
        )
    finished: dict[str, Any] = {}
    for domain, module, config in plan:
        run_dir = out / domain
        stored = config.to_dict() if hasattr(config, "to_dict") else dataclasses.asdict(config)
        if (run_dir / "results.json").is_file():
            try:
                results = json.loads((run_dir / "results.json").read_text(encoding="utf-8"))
                differ = config_differences(results["config"], plain_json(stored))
            except (OSError, ValueError, KeyError, TypeError) as exc:
                raise _UsageError(
                    f"--resume: {run_dir / 'results.json'} is not a results.json of torchcbl "
                    f"reproduce ({_one_line(exc)}); expected the --out directory of a stopped "
                    "run"
                ) from None
            if differ:
                raise _UsageError(
                    f"--resume: the {domain} run in {run_dir} finished with other settings: "
                    f"{'; '.join(differ)}; {again}"
                )
            finished[domain] = results
            continue
        try:
            module.resumable_seeds(config, run_dir)
        except ResumeError as exc:  # other settings or seeds (say which to give), other code
            fix = (
                again
                if exc.kind in ("settings", "seeds")
                else "resume with the code it was started with (the versions named there), or "
                "start a new run without --resume"
            )
            raise _UsageError(f"--resume: the {domain} run: {exc.core}; {fix}") from None
    return finished


def _output_dir(path: Path, flag: str) -> Path:
    """``path`` as a directory to write into, or a one-line error: it (or a parent) exists as a
    file, or the directory it is (or would be made in) cannot be written. A path with no name
    of its own (``.``, ``..``, ``""``) is made absolute, so that a fresh ``-2`` beside it is
    named after the directory it means."""
    if path.name in ("", ".", ".."):
        path = path.resolve()
    for p in (path, *path.parents):
        if p.exists():
            if not p.is_dir():
                where = "it is a file" if p == path else f"{p} is a file"
                raise _UsageError(
                    f"{flag} {path} cannot be a directory: {where}; expected a new or empty "
                    "directory path"
                )
            _check_writable(p, f"{flag} {path}")
            break
    return path


def _check_writable(directory: Path, what: str) -> None:
    """A one-line error if no file can be made in ``directory`` (read-only, not one's own):
    found before a run starts, not when its first file is written. A file is made and removed
    to know, as permission bits alone do not tell (root, read-only mounts, ACLs)."""
    import tempfile

    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError as exc:
        raise _UsageError(
            f"{what}: cannot write in {directory} ({exc.strerror or exc}); choose a directory "
            "you can write to"
        ) from None


def _output_file(path: Path, flag: str) -> Path:
    """``path`` as a file to write, or a one-line error: it is a directory, or its directory is
    missing, a file or not writable."""
    if path.is_dir():
        raise _UsageError(f"{flag} {path} is a directory; expected a file path")
    if not path.parent.is_dir():
        what = "is a file" if path.parent.exists() else "does not exist"
        raise _UsageError(f"cannot write {path}: directory {path.parent} {what}")
    _check_writable(path.parent, f"{flag} {path}")
    return path


def _fresh_dir(out: Path) -> Path:
    """``out`` if it is new or empty, else the first free ``out-2``, ``out-3``, ... (a run
    directory is never overwritten)."""
    candidate, n = out, 1
    while candidate.exists() and any(candidate.iterdir()):
        n += 1
        candidate = out.with_name(f"{out.name}-{n}")
    try:
        candidate.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # e.g. out is writable, its parent (for out-2) is not
        raise _UsageError(
            f"--out {out}: cannot make {candidate} ({exc.strerror or exc}); choose a directory "
            "you can write to"
        ) from None
    return candidate


def latest_run(out: Path = Path("runs/reproduce")) -> Path:
    """The newest finished run (one holding ``summary.md``) among ``out``, ``out-2``, ...
    (what :func:`_fresh_dir` writes), else ``out``: for scripts that read a reproduction."""
    pattern = re.compile(re.escape(out.name) + r"(-[0-9]+)?")
    done = [
        p
        for p in out.parent.glob(out.name + "*")
        if pattern.fullmatch(p.name) and (p / "summary.md").is_file()
    ]
    return max(done, key=lambda p: (p / "summary.md").stat().st_mtime) if done else out


def _replace_seeds(config: Any, n_seeds: int) -> Any:
    fields = {f.name for f in dataclasses.fields(config)}
    if "seeds" in fields:
        return dataclasses.replace(config, seeds=tuple(range(n_seeds)))
    if "n_seeds" in fields:
        return dataclasses.replace(config, n_seeds=n_seeds)
    raise _UsageError(f"--seeds is not supported by {type(config).__name__}")


def _env_named(env: dict[str, Any]) -> str:
    """A session's env (config.json's ``"env"``) by its gymnasium id, else by its class (what
    resume compares of an env made directly), as a message names it."""
    if env.get("id"):
        return f"env id {env['id']!r}"
    kept = env.get("class")
    if isinstance(kept, str) and kept:
        return f"env {kept} made directly (no gymnasium id)"
    return "env made directly (no gymnasium id; its class not recorded)"


def _session_domain(session: Path, asked: str | None, *, teach: bool = False) -> str:
    """The domain a teaching session was taught in, read from its config.json; ``asked`` (the
    user's --domain, if any) must agree with it."""
    from torchcbl.session import IncompatibleRunDirError, _sessions_below, load_config

    if not session.exists():
        if teach and asked is not None:  # a typo, or a session not started yet
            raise _UsageError(
                f"--resume: {session} does not exist {_cwd_said(session)}, so there is no "
                "session to resume; check the path"
                + ("" if "~" in str(session) else f", or {_start_without_resume(session, asked)}")
            )
        raise _UsageError(f"{session} does not exist; {_SESSION_HINT}")
    if not session.is_dir():
        raise _UsageError(f"{session} is a file; {_SESSION_HINT}")
    if not (session / "config.json").exists():
        below = _sessions_below(session)
        if below:
            shown = ", ".join(str(p) for p in below)
            raise _UsageError(
                f"{session} is not a teaching session but holds sessions: {shown}"
                f"{' ...' if len(below) == 5 else ''}; pass one of them"
            )
        if teach and asked is not None:
            refused = _new_session_refusal(session)
            if refused is None:
                raise _UsageError(
                    f"--resume: {session} holds no config.json, so there is no session to "
                    f"resume; {_start_without_resume(session, asked)}"
                )
            raise _UsageError(  # the start's refusal says why and what to do
                f"--resume: there is no session to resume in {session} (it holds no "
                f"config.json), and no new session can start there either: {refused}"
            )
        raise _UsageError(f"{session} holds no config.json; {_SESSION_HINT}")
    try:
        config = load_config(session)
    except IncompatibleRunDirError as exc:
        raise _UsageError(str(exc)) from None
    env = config.get("env") or {}
    shape = (env.get("n_features"), env.get("n_actions"))
    by_space = {k: d for k, d in _SPACES.items() if k[:2] == shape}
    space = env.get("observation_space")
    if space is not None:  # (a session too old to have stored it goes by its shape alone)
        by_space = {k: d for k, d in by_space.items() if k[2] == space}
    domain = _ENV_IDS.get(env.get("id") or "") or next(iter(by_space.values()), None)
    sizes = f"{_counted(shape[0], 'feature')}, {_counted(shape[1], 'action')}"
    described = f"{_env_named(env)}, {sizes}" + (f", observations {space}" if space else "")
    if domain is None:
        raise _UsageError(
            f"{session} was taught in an env torchcbl does not know ({described}); "
            + (
                "resume it in Python with torchcbl.ConfidentTeacher.resume"
                if teach
                else "evaluate it in Python with torchcbl.load_policy and torchcbl.evaluate_policy"
            )
        )
    if teach and not env.get("id"):
        raise _UsageError(
            f"{session} was not taught by torchcbl teach (its env was not made by "
            "gymnasium.make: a reproduction's or a script's session), so teach cannot make its "
            "env again; start a new session with another --run-dir"
        )
    if teach and env.get("id") not in _ENV_IDS:  # another env of a domain's space: teach
        # would make its domain's env, which the session was not taught in
        made = " or ".join(repr(i) for i in _ENV_IDS)
        raise _UsageError(
            f"{session} was taught in the env {env.get('id')!r}, not in one teach makes "
            f"({made}), so teach cannot make its env again; resume it in Python, "
            f"torchcbl.ConfidentTeacher.resume({str(session)!r}, "
            f"gymnasium.make({env.get('id')!r}, ...), teacher)"
        )
    if asked is not None and asked != domain:
        mistake = f"{session} is a {domain} session ({described}), not a {asked} one"
        done = _done_text(session, domain) if teach else None
        if done is not None:  # resuming it in its own domain is refused too: say what is left
            raise _UsageError(f"{mistake}, and it is done: {done}")
        raise _UsageError(
            f"{mistake}; "
            + (
                f"resume it with torchcbl teach {domain} --resume --run-dir {_shell(session)}"
                if teach
                else f"pass --domain {domain} or leave --domain out"
            )
        )
    model = config["model"]
    own = model.get("class", "GaussianMixtureSet")
    if own != "GaussianMixtureSet":  # a user's class (a subclass): only Python can make it
        made = f"model={own}(...)) made as the session made it, {own}(**{model.get('args')})"
        raise _UsageError(
            f"{session}'s model is a {own}, a class of its own (a run directory rebuilds "
            "torchcbl's GaussianMixtureSet alone), which the command line cannot make; "
            + (
                f"resume it in Python, torchcbl.ConfidentTeacher.resume({str(session)!r}, env, "
                f"teacher, {made}"
                if teach
                else f"evaluate it in Python, torchcbl.load_policy({str(session)!r}, {made}, "
                "with torchcbl.evaluate_policy"
            )
        )
    return domain


def _cwd_said(path: Path) -> str:
    """Where a path that does not exist was looked for: "(relative paths are taken from the
    working directory, CWD)", and that a '~' the shell was not let expand stays a '~'."""
    tilde = "; a '~' in quotes is not expanded: leave it unquoted" if "~" in str(path) else ""
    return f"(relative paths are taken from the working directory, {os.getcwd()}{tilde})"


def _start_without_resume(run_dir: Path, domain: str) -> str:
    """How ``teach --resume`` of a folder holding no session starts one there instead."""
    return (
        "leave out --resume to start a new session there: "
        f"torchcbl teach {domain} --run-dir {_shell(run_dir)}"
    )


def _new_session_refusal(run_dir: Path) -> str | None:
    """Why ``teach`` (without --resume) would not start a new session in ``run_dir``, as one
    line naming ``--run-dir``, or None where it would (the store's rule: missing, empty, or
    holding only what torchcbl leaves where no session started); read-only."""
    from torchcbl.errors import IncompatibleRunDirError
    from torchcbl.session import _check_new_session_dir

    try:
        _check_new_session_dir(run_dir, name="--run-dir")
    except IncompatibleRunDirError as exc:
        return _one_line(exc)
    return None


def _session_map_exists(session: Path, domain: str) -> None:
    """A one-line error if a corridor session's own map file (``teach corridor --map PATH``
    keeps it by its full path; the session keeps the map's digest) is not there any more, or
    has changed since the session started: neither evaluate nor teach --resume takes another
    map, so the way on is to put the file back as it was."""
    if domain != "corridor":
        return
    try:
        _experiment_module("corridor").check_session_map(session)
    except ValueError as exc:
        raise _UsageError(_one_line(exc)) from None


def _cmd_evaluate(args: argparse.Namespace) -> int:
    session = Path(args.run_dir)
    domain = _session_domain(session, args.domain)
    _session_map_exists(session, domain)
    module = _experiment_module(domain)
    from torchcbl.evaluation import SEED_RESULT
    from torchcbl.session import IncompatibleRunDirError

    # without --seed, the domain's own default: driving's is the segment a reproduction's
    # session's run evaluated its seed's policies on (else 0), the corridor's 0
    seed = {} if args.seed is None else {"seed": args.seed}
    traffic = {}  # driving: the held-out twin of the session's traffic (train's: eval)
    if args.scenario is not None:
        if domain != "driving":
            raise _UsageError(
                f"--scenario applies only to a driving session; {session} is a {domain} "
                "session (it is driven on the map it was taught on): leave --scenario out"
            )
        traffic = {"scenario": _scenario_option(args.scenario)}
    try:
        with warnings.catch_warnings(record=True) as said:  # each one line below
            warnings.simplefilter("always")
            report = module.evaluate_saved_policy(session, n_steps=args.steps, **seed, **traffic)
    except (IncompatibleRunDirError, ValueError) as exc:  # e.g. a robot its config lacks
        raise _UsageError(_one_line(exc)) from None
    if (
        not seed
        and not traffic
        and domain == "driving"
        and module.session_eval_segment(session) is not None
    ):
        print(
            f"torchcbl evaluate: note: driving held-out segment {report['eval_segment']}, the "
            "one its run evaluated this seed's policies on "
            f"({Path(os.path.abspath(session)).parent.parent / SEED_RESULT}); "
            "--seed S drives segment S",
            file=sys.stderr,
        )
    for w in said:  # e.g. a corridor session that does not say which robot it was taught on
        text = _one_line(w.message)
        held = getattr(module, "NotHeldOutWarning", None)  # (driving's; said the CLI's way)
        unknown = getattr(module, "HeldOutUnknownWarning", None)  # (its advice is the CLI's)
        if held is not None and isinstance(w.message, held) and not isinstance(w.message, unknown):
            text = (
                f"{_one_line(w.message.road)}; for held-out ones give another segment (--seed S) "
                "or base seed (--scenario NAME|FILE.json)"
                + (
                    ""
                    if args.scenario is None
                    else ", or leave --scenario out: evaluate then drives the held-out twin of "
                    "the session's traffic"
                )
            )
        print(f"torchcbl evaluate: warning: {text}", file=sys.stderr)
    print(json.dumps(report, indent=2))
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from torchcbl.session import (
        CONFIG_NAME,
        CorruptSessionError,
        IncompatibleRunDirError,
        _sessions_below,
        describe,
    )

    path = Path(args.run_dir)
    if path.is_dir() and not (path / CONFIG_NAME).exists() and os.access(path, os.R_OK | os.X_OK):
        not_searched: list[tuple[Path, str]] = []
        below = _sessions_below(path, limit=None, depth=_SHOW_DEPTH, not_searched=not_searched)
        # folders this user may not list: the sessions in them are not counted
        unseen = [f"{folder}: cannot be searched: {why}" for folder, why in not_searched]
        if not below:
            raise _UsageError(
                f"{path} holds no teaching session (no {CONFIG_NAME} in it, nor in a session "
                f"directory up to {_SHOW_DEPTH} levels below"
                + (f"; not searched: {'; '.join(unseen)}" if unseen else "")
                + f"); {_SESSION_HINT}"
            )
        entries: list[dict[str, Any]] = []
        head = f"{path} holds {_counted(len(below), 'teaching session')}"
        if unseen:
            head += (
                f" in the folders it could search ({_counted(len(unseen), 'folder')} it could "
                "not, listed last)"
            )
        lines = [f"{head}:"]
        for session in below:
            try:
                summary = describe(session)
            # OSError: what describe does not turn into its own errors (a file of the
            # session the file system fails to read); the other sessions are listed still
            except (IncompatibleRunDirError, CorruptSessionError, OSError) as exc:
                entries.append({"run_dir": str(session), "error": _one_line(exc)})
                lines.append(f"{session}: cannot be read: {_one_line(exc)}")
            else:
                entries.append(summary.to_dict())
                lines.append(summary.line())
        if args.json:
            skipped = [{"folder": str(folder), "error": why} for folder, why in not_searched]
            print(
                json.dumps(
                    {"folder": str(path), "sessions": entries, "not_searched": skipped}, indent=2
                )
            )
        else:
            print("\n".join(lines + unseen))
        return 0
    try:
        os.stat(path)
    except FileNotFoundError:  # (describe's words for it name the Python call)
        raise _UsageError(
            f"{path} does not exist; {_SESSION_HINT}. Check the path {_cwd_said(path)}"
            + (
                ""
                if "~" in str(path)
                else f", or start a session there: torchcbl teach corridor --run-dir "
                f"{_shell(path)} (or teach driving)"
            )
        ) from None
    except OSError:
        pass  # (a permission, a loop of links: describe says it)
    try:
        summary = describe(path)
    except IncompatibleRunDirError as exc:  # not a session, or one this user may not read
        raise _UsageError(_one_line(exc)) from None
    print(json.dumps(summary.to_dict(), indent=2) if args.json else summary.text())
    return 0


# How deep `torchcbl show DIR` looks for sessions: runs/reproduce/driving/seed_0/sessions/arm_a
# from runs/ is 5 levels down
_SHOW_DEPTH = 5


def _load_episodes(path: Path) -> list[Any]:
    replay = importlib.import_module("sumo_scenarios.replay")
    if not path.exists():
        raise _UsageError(f"{path} does not exist; {_EPISODES_HINT}")
    if path.is_dir() and (path / "config.json").is_file():  # a teaching session
        try:
            return replay.session_episodes(path)
        except (ValueError, TypeError) as exc:
            raise _UsageError(str(exc)) from None
    if not path.is_file():
        raise _UsageError(f"{path} is a directory; {_EPISODES_HINT}")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise _UsageError(f"{path} is not JSON ({exc}); {_EPISODES_HINT}") from None
    keys = {"scenario", "sim", "episode_seed", "start_lane", "actions"}
    if not isinstance(data, list) or not all(
        isinstance(d, dict) and keys <= d.keys() for d in data
    ):
        if isinstance(data, dict):
            got = f"a JSON object with keys {sorted(data)[:6]}"
        elif isinstance(data, list):
            got = "a JSON list whose items are not recorded episodes"
        else:
            got = f"a JSON {type(data).__name__}"
        nearby = sorted(path.parent.glob("seed_*/episodes.json"))[:3]
        hint = f"this run's episodes are in {', '.join(map(str, nearby))}" if nearby else ""
        raise _UsageError(
            f"{path} is {got}, not a list of recorded episodes (each with {sorted(keys)}); "
            f"{hint or _EPISODES_HINT}"
        )
    try:
        return [replay.EpisodeRecord.from_dict(d) for d in data]
    except (TypeError, ValueError, KeyError) as exc:
        raise _UsageError(f"{path} holds an episode this version cannot read ({exc})") from None


def _cmd_replay(args: argparse.Namespace) -> int:
    replay = importlib.import_module("sumo_scenarios.replay")
    path = Path(args.episodes)
    episodes = _load_episodes(path)
    if not episodes:
        raise _UsageError(f"{path} holds no episodes")
    if args.list:
        for i, ep in enumerate(episodes):
            print(f"{i:4d}  {ep.label or '-':50s} {len(ep.actions):6d} steps")
        return 0
    matches = [i for i, ep in enumerate(episodes) if args.label and args.label in (ep.label or "")]
    index = matches[0] if matches else args.episode
    if args.label and not matches:
        raise _UsageError(f"no episode label contains {args.label!r}; see --list")
    if not 0 <= index < len(episodes):
        raise _UsageError(f"--episode must be in [0, {len(episodes)}), got {index}; see --list")
    record = episodes[index]
    session = path.is_dir()
    # beside the JSON, or beside (not in) a session's directory ("." too)
    stem = path.resolve() if session else path.with_suffix("")
    gif = Path(args.gif) if args.gif else stem.with_name(f"{stem.name}-{index}.gif")
    fcd = Path(args.fcd) if args.fcd else stem.with_name(f"{stem.name}-{index}.fcd.xml")
    _output_file(gif, "--gif")
    if gif.suffix.lower() != ".gif":  # the writer picks its format by the name
        raise _UsageError(
            f"--gif {gif}: expected a file name ending in .gif, e.g. {gif.with_suffix('.gif')}"
        )
    _output_file(fcd, "--fcd")
    # EP.fcd.xml(.gz) -> EP.sumocfg
    cfg = fcd.with_name(fcd.name.removesuffix(".gz").replace(".fcd.xml", "") + ".sumocfg")
    _replay_outputs_spare(path, gif, fcd, cfg)
    # what the replay needs (listing needs none of it), before anything runs or is written
    _check_importable([*_DOMAIN_NEEDS["driving"], "imageio", "matplotlib"])
    # (_refuse_commas below refuses this too, but names the fcd-replay input, not --fcd)
    if "," in fcd.name:
        raise _UsageError(
            f"--fcd {fcd}: the .sumocfg beside it names its fcd-replay input after it, and SUMO "
            "splits file lists at commas; give --fcd a name without a comma"
        )
    try:  # the .sumocfg names the shipped files too: refused before the FCD is written
        replay._refuse_commas(fcd, cfg)
    except ValueError as exc:  # the package under a path with a comma
        raise _UsageError(str(exc)) from None
    if session:  # the session logged what it saw: the replay must see the same
        try:
            replay.session_episodes(path, check=[index])
        except ValueError as exc:
            raise _UsageError(str(exc)) from None
        print(f"episode {index}: the replay equals the session's log, observation for observation")
    print(f"episode {index}: {record.label or '-'} ({len(record.actions)} steps)")
    replay.export_fcd(record, fcd)
    print(f"FCD written to {fcd}")
    try:
        cfg = replay.write_sumocfg(record, fcd, cfg)
    except ValueError as exc:  # its one check not made above (the commas and directories
        # were): the FCD just written does not read back as this record's
        raise _UsageError(str(exc)) from None
    print(f"SUMO configuration written to {cfg} (open with: sumo-gui -c {_shell(cfg)})")
    replay.render_gif(record, gif, every=args.every, max_frames=args.max_frames)
    steps = len(record.actions)
    frames = len(range(0, steps + 1, args.every))  # the reset's frame and one per step
    if args.max_frames is not None and args.max_frames < frames:
        frames = args.max_frames
        shown = f"the first {(frames - 1) * args.every} of {steps} timesteps"
    else:
        shown = f"all {steps} timesteps"
    print(f"GIF written to {gif} ({frames} frames, every {args.every} timestep(s): {shown})")
    return 0


def _replay_outputs_spare(source: Path, gif: Path, fcd: Path, cfg: Path) -> None:
    """A one-line error, before anything is written, if a file replay writes (the GIF, the
    FCD, the .sumocfg and the fcd-replay input beside it) is the episodes file being replayed or
    a file of the session being replayed (its log, its config), or is another of the outputs:
    writing it would destroy the recording, or one output would overwrite another; or if it is
    a directory (the GIF and FCD are checked so before, the two files beside the FCD here)."""
    replay = importlib.import_module("sumo_scenarios.replay")
    replay_input = replay._beside_fcd(fcd, ".replay.xml")  # as write_sumocfg names it
    outputs = [
        (f"--gif {gif}", gif),
        (f"--fcd {fcd}", fcd),
        (f"the .sumocfg of --fcd, {cfg},", cfg),
        (f"the fcd-replay input of --fcd, {replay_input},", replay_input),
    ]
    source = source.resolve()
    seen: dict[Path, str] = {}
    for what, out in outputs:
        target = out.resolve()
        if target == source or (source.is_dir() and source in target.parents and target.exists()):
            kept = "the episodes file" if target == source else f"a file of the session {source}"
            raise _UsageError(
                f"{what} is {kept} being replayed: writing it would destroy the recording; "
                "choose another path (or leave --gif/--fcd out: the default is beside it)"
            )
        if out.is_dir():
            raise _UsageError(
                f"{what} is a directory; expected a file path: move it away or give "
                "--fcd another name"
            )
        if target in seen:
            raise _UsageError(
                f"{what} is also {seen[target].rstrip(',')}: one output would overwrite the "
                "other; give --gif and --fcd paths apart"
            )
        seen[target] = what


def _cmd_plot(args: argparse.Namespace) -> int:
    run_dir = Path(args.run_dir)
    results_path = run_dir / "results.json"
    if not results_path.is_file():
        below = _reproduction_run_dirs(run_dir)
        if below:
            raise _UsageError(
                f"{run_dir} has no results.json but holds run directories of torchcbl "
                f"reproduce: {', '.join(str(p) for p in below)}; pass one of them"
            )
        raise _UsageError(
            f"{results_path} does not exist; expected a run directory written by "
            "torchcbl reproduce (e.g. runs/reproduce/corridor)"
        )
    try:
        results = json.loads(results_path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise _UsageError(f"{results_path} is not JSON ({exc})") from None
    domain = results.get("domain") if isinstance(results, dict) else None
    if domain is None and isinstance(results, dict) and {"table", "sweep"} <= results.keys():
        png = run_dir / "learning_curves.png"
        where = (
            f"whose plot is {png}, written by the sweep"
            if png.is_file()
            else f"whose sweep left no plot ({png}: e.g. run_benchmark(..., plots=False), or "
            "stopped before drawing it)"
        )
        raise _UsageError(
            f"{results_path} is a torchcbl benchmark's, {where}; run the same sweep again "
            "(torchcbl benchmark, or run_benchmark with plots=True) to draw it anew from its "
            "cached cells; torchcbl plot takes a run directory of torchcbl reproduce"
        )
    if domain not in _DOMAINS:
        raise _UsageError(
            f"{results_path} names domain {domain!r}; expected one of {sorted(_DOMAINS)} "
            "(a results.json written by torchcbl reproduce)"
        )
    _check_figures_writable(run_dir)
    try:
        written = _experiment_module(domain).plot_results(results, run_dir)
    except FileNotFoundError as exc:
        raise _UsageError(_one_line(exc)) from None
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise _UsageError(
            f"{results_path} lacks what the {domain} figures need ({type(exc).__name__}: "
            f"{_one_line(exc)}); expected the whole results.json written by torchcbl reproduce"
        ) from None
    for path in written:
        print(path)
    return 0


def _reproduction_run_dirs(folder: Path) -> list[Path]:
    """The run directories of torchcbl reproduce directly below ``folder`` (its --out): those
    whose results.json names a domain. A benchmark's results.json, or any other, is not one."""
    found: list[Path] = []
    if not folder.is_dir():
        return found
    for path in sorted(folder.glob("*/results.json")):
        try:
            results = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):  # unreadable, not UTF-8 or not JSON: not a run's
            continue
        domain = results.get("domain") if isinstance(results, dict) else None
        if isinstance(domain, str) and domain in _DOMAINS:
            found.append(path.parent)
    return found


def _check_figures_writable(run_dir: Path) -> None:
    """A one-line error, before any figure is drawn, if no file can be made in ``run_dir``
    (a read-only mount, another user's run; found as :func:`_check_writable` does)."""
    import tempfile

    try:
        with tempfile.TemporaryFile(dir=run_dir):
            pass
    except OSError as exc:
        raise _UsageError(
            f"cannot write the figures into {run_dir} ({exc.strerror or exc}): plot writes "
            f"them beside its results.json; copy the run directory somewhere you can write "
            f"(cp -r {_shell(run_dir)} DIR) and plot the copy"
        ) from None


# What the teach command needs per domain: the gymnasium id (registered on importing the
# package), the module with the text view / key map, the paper's teaching settings, and the
# "module:function" giving the domain experiment's (env kwargs, confidence rule, learner from a
# seed), so that a person's session compares with the reproduction's.
_TEACH = {
    "corridor": (
        "corridor",
        "torchcbl/Corridor-v0",
        "corridor.human",
        dict(accuracy_window=20, target_accuracy=0.9, autonomous_episodes_to_stop=10),
        "corridor.experiment:teaching_setup",
    ),
    "driving": (
        "sumo_scenarios",
        "torchcbl/Driving-v0",
        "sumo_scenarios.human",
        dict(
            accuracy_window=150, target_accuracy=0.8, burst=10, max_new=10, max_demonstrations=650
        ),
        "sumo_scenarios.experiment:teaching_setup",
    ),
}


def _teach_epilog() -> str:
    """teach --help's epilog: what the status line shown at each request counts, each
    domain's accuracy window and target, and when a domain's teaching ends (from
    :data:`_TEACH`'s settings)."""
    windows = "; ".join(
        f"{domain} W = {s['accuracy_window']} and {100 * s['target_accuracy']:g}%"
        for domain, (*_, s, _) in _TEACH.items()
    )
    corridor, driving = _TEACH["corridor"][3], _TEACH["driving"][3]
    return (
        "At each request a status line says where the session stands: decision #N (this "
        "request's number: one more than the requests you have answered), step (the steps "
        "taken), phase (noninteractive: the agent "
        "asks you at every step; confident: it acts on its own where it is sure and asks you "
        "where it is not), demonstrations (the keys you gave), prediction accuracy (the share "
        "of your last W demonstrations on which the agent's own choice, made before it learned "
        "from them, was your key; the non-interactive phase ends once W demonstrations are in "
        "that window and it reaches the target) and autonomy (the share of the last W "
        "confident-phase steps the agent took on its own, without asking; - before the "
        f"confident phase). The window and the target: {windows}. Teaching ends after --steps, "
        f"and in the corridor, done, once the agent drove "
        f"{corridor['autonomous_episodes_to_stop']} circuits in a row on its own, each without "
        f"a wall contact; in driving at {driving['max_demonstrations']} demonstrations "
        "(--resume goes past it)."
    )


_EVALUATE_EPILOG = (
    "The report's fields. Corridor: map (the map driven: a shipped map's name or a map file's "
    "path), map_sha256 (its digest, which tells maps of one name apart), world (the robot's "
    "settings, WorldConfig's fields), steps (the actions run; an episode ends at the end of a "
    "circuit or at the env's step cap, and another begins), circuits_completed (the circuits "
    "the robot completed: back at its start, along the route), circuits_clean (those of them "
    "without a wall contact: each a success), wall_contacts (the steps on which the robot "
    "touched a wall, over every episode: a step counts once). Driving: steps (the timesteps "
    "driven), eval_segment (the road segment driven, --seed), collision_pct (the percentage, "
    "0 to 100, of timesteps on which the car overlapped another car), lanes (the fraction, "
    "0 to 1, of timesteps in each lane, summing to 1, in the order of lane_names), lane_names "
    "(the lanes' names, right shoulder first), scenario (the traffic driven, its "
    "TrafficScenario fields), held_out (false where that is road the session was taught on, "
    "or the session its prior demonstrations were read from was; null where that cannot be "
    "told, with a warning: prior demonstrations from a .npz file or arrays, or read by a "
    "torchcbl before 2026-11-28, whose session is not recorded, or whose session is not "
    "there any more or holds others now; or a session written before 2026-11-27 whose traffic "
    "was kept only as text, so its base seed is not known, on a segment its own episodes "
    "drove; else true), "
    "start_lane (the lane it started in, 0 the right shoulder), sim (the SUMO settings, "
    "SimConfig's fields)."
)


#: per domain, the "module:function" making again from a session's config what gymnasium.make
#: was given for its env, objects too: (kwargs, {argument: why it cannot be made}), as the
#: domain's evaluate and replay make them
_MAKE_KWARGS = {
    "corridor": "corridor.experiment:_session_make_kwargs",
    "driving": "sumo_scenarios.replay:_session_make_kwargs",
}


def _scenario_option(text: str) -> Any:
    """``--scenario NAME|FILE.json``: a shipped scenario's name as given (a session keeps it by
    name, as it keeps teach's default), else the ``TrafficScenario`` the JSON file's fields make
    (``sumo_scenarios.scenarios.load_scenario``, whose checks are TrafficScenario's own); a
    one-line error for anything it refuses."""
    from sumo_scenarios.scenarios import SCENARIOS, load_scenario

    try:
        scenario = load_scenario(text)
    except ValueError as exc:
        raise _UsageError(f"--scenario: {_one_line(exc)}") from None
    return text if text in SCENARIOS else scenario


def _check_session_traffic(
    run_dir: Path, session_kwargs: dict[str, Any], text: str, given: Any
) -> None:
    """``teach driving --resume --scenario``: a one-line error unless ``given`` (a shipped
    name or a ``TrafficScenario``) is the traffic the session drives (from what gymnasium.make
    was given for it, ``session_kwargs``: its scenario, its DrivingConfig's, else the
    default); its name aside, which changes nothing the traffic does."""
    from sumo_scenarios.env import DrivingConfig
    from sumo_scenarios.scenarios import compared_fields, get_scenario

    config = session_kwargs.get("config")
    kept = (
        config.scenario
        if isinstance(config, DrivingConfig)
        else session_kwargs.get("scenario", DrivingConfig().scenario)
    )
    try:
        own = get_scenario(kept)
    except ValueError as exc:  # a name this version does not ship
        raise _UsageError(f"{run_dir}: its traffic cannot be made ({_one_line(exc)})") from None
    mine, theirs = compared_fields(get_scenario(given)), compared_fields(own)
    differ = [f"{k} {mine[k]} (the session's: {theirs[k]})" for k in mine if mine[k] != theirs[k]]
    if differ:
        raise _UsageError(
            f"--scenario {text}: its traffic differs from the traffic the session in {run_dir} "
            f"is taught on ({own.name!r}) in {'; '.join(differ)}; a resumed session drives its "
            "own traffic: leave --scenario out with --resume (or teach this traffic in a new "
            "session, another --run-dir)"
        )


def _check_session_map_given(
    run_dir: Path, session_kwargs: dict[str, Any], text: str, given: Any
) -> None:
    """``teach corridor --resume --map``: a one-line error unless ``given`` (the
    ``CorridorMap`` that ``--map text`` names) is the map the session is taught on: the same
    digest (``corridor.maps.map_digest``, which ``CorridorEnv.describe_inputs()`` gives and
    resume compares) as the one the session's config keeps, or, for a session that keeps
    none, as its own map's (from what gymnasium.make was given for it, ``session_kwargs``:
    a name, a path or a ``CorridorMap``, else the env's default); its name and description
    aside, which change nothing the robot drives. What differs is said field by field, as
    resume says a kept object's fields (``torchcbl.session``)."""
    from corridor.env import DEFAULT_MAP
    from corridor.maps import CorridorMap, load_map, map_digest
    from torchcbl.session import (
        _form_differences,
        _not_compared,
        _object_form,
        _shortened,
        load_config,
    )

    own = session_kwargs.get("corridor_map", DEFAULT_MAP)
    try:
        own_map = own if isinstance(own, CorridorMap) else load_map(own)
    except ValueError as exc:  # (its own map file is checked before: a shipped map gone)
        raise _UsageError(f"{run_dir}: its map cannot be made ({_one_line(exc)})") from None
    inputs = (load_config(run_dir).get("env") or {}).get("inputs") or {}
    kept = inputs.get("corridor_map_sha256")
    kept = kept if isinstance(kept, str) else map_digest(own_map)
    now = map_digest(given)
    if now == kept:
        return
    mine, theirs = (json.loads(json.dumps(_object_form(m))) for m in (given, own_map))
    differ = [  # (path, the session's, given's), e.g. ("nodes.B[0]", 2.0, 2.5)
        (path.lstrip("."), b, a)
        for path, b, a in _form_differences(theirs, mine, _not_compared(given), "")
    ]
    by_field: dict[str, list[tuple[str, Any, Any]]] = {}
    for entry in differ:  # a few values each with both sides; many (another map) by field
        by_field.setdefault(re.split(r"[.\[]", entry[0], maxsplit=1)[0], []).append(entry)
    fields: list[str] = []
    for field, entries in by_field.items():
        if len(differ) > 4 and len(entries) > 1:
            fields.append(f"{field} ({len(entries)} values)")
        else:
            fields += [
                f"{p} {_shortened(a)} (the session's: {_shortened(b)})" for p, b, a in entries
            ]
    what = (
        "; ".join(fields)
        or (  # its own map is not the one it kept the digest of
            f"its digest {now[:12]}... (the session's map's: {kept[:12]}...)"
        )
    )
    named = (
        f"the map {own_map.name!r} it keeps whole" if isinstance(own, CorridorMap) else repr(own)
    )
    raise _UsageError(
        f"--map {text}: another map than the one the session in {run_dir} is taught on "
        f"({named}), differing in {what}; a resumed session drives its own map: leave --map "
        "out with --resume (or teach this map in a new session, another --run-dir)"
    )


def _resume_env_kwargs(run_dir: Path, domain: str) -> dict[str, Any]:
    """What gymnasium.make was given for a session's env, to make it again on --resume: the
    kwargs its config.json records (an object, a ``CorridorMap`` or ``DrivingConfig`` a
    session begun in Python was given, made again from what the session keeps of it) and,
    where it records an int cap, ``max_episode_steps`` (a benchmark cell's driving env was made
    with gymnasium.make's max_episode_steps=1000, a TimeLimit that teach's own env lacks; a
    cap equal to the env's own, as teach's corridor sessions record, changes nothing). A
    one-line error naming the Python call where an argument cannot be made again."""
    from torchcbl.benchmark import _import
    from torchcbl.session import load_config

    config = load_config(run_dir)
    env = config.get("env") or {}
    made, unknown = _import(_MAKE_KWARGS[domain])(config)
    if unknown:
        names = sorted(unknown)
        given = ", ".join(f"{n}=<the {n} it was taught with>" for n in names)
        raise _UsageError(
            f"{run_dir}'s env was made with {', '.join(names)} given as an object, which teach "
            f"--resume cannot make again: {_one_line(unknown[names[0]])}; resume it in Python, "
            f"torchcbl.ConfidentTeacher.resume({str(run_dir)!r}, gymnasium.make("
            f"{env.get('id')!r}, {given}), teacher)"
        )
    cap = env.get("max_episode_steps")  # (None: no cap, or a session too old to keep one)
    if isinstance(cap, int) and not isinstance(cap, bool) and cap >= 1:
        made["max_episode_steps"] = cap
    return made


_PRIOR_EXPECTED = (
    "expected a .npz file holding the arrays 'observations' [N, D] and 'actions' [N] (as "
    "numpy.savez(path, observations=..., actions=...) writes them), or a teaching session "
    "directory (its training set: its own prior demonstrations, then its labels, relabelled "
    "as its strategy relabels)"
)


def _read_prior_demonstrations(path: Path) -> tuple[Any, Any]:
    """``--prior-demonstrations``: (observations, actions) from a .npz file or a session
    directory, or a one-line error. Their shapes and values are checked by ConfidentTeacher."""
    import numpy as np

    flag = f"--prior-demonstrations {path}"
    if path.is_dir() and not (path / "config.json").exists():
        from torchcbl.session import _sessions_below

        below = _sessions_below(path)
        if below:  # a run directory (runs/reproduce/corridor) or a folder of sessions
            shown = ", ".join(str(p) for p in below)
            raise _UsageError(
                f"{flag}: {path} is not a teaching session but holds sessions: {shown}"
                f"{' ...' if len(below) == 5 else ''}; pass one of them"
            )
        raise _UsageError(f"{flag}: {path} holds no config.json; {_PRIOR_EXPECTED}")
    if path.is_dir():
        from torchcbl.errors import CorruptSessionError, IncompatibleRunDirError
        from torchcbl.session import load_demonstrations

        try:  # its training set: its own prior first, relabelled as its strategy relabels
            demonstrations = load_demonstrations(path)
        except (IncompatibleRunDirError, CorruptSessionError) as exc:
            raise _UsageError(f"{flag}: {_one_line(exc)}") from None
        if not len(demonstrations[1]):  # (ConfidentTeacher's says "leave it out (None)")
            raise _UsageError(
                f"{flag}: that session holds no demonstrations yet; teach it first (torchcbl "
                "teach ... --resume), or leave --prior-demonstrations out"
            )
        # as read: the new session records which session and steps they came from
        return demonstrations
    if not path.is_file():
        raise _UsageError(f"{flag}: no such file or directory; {_PRIOR_EXPECTED}")
    try:
        npz = np.load(path, allow_pickle=False)
    except Exception as exc:  # not a numpy file, cut short, pickled arrays: numpy's errors
        raise _UsageError(
            f"{flag}: not a readable .npz ({type(exc).__name__}: {_one_line(exc)}); "
            f"{_PRIOR_EXPECTED}"
        ) from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise _UsageError(f"{flag}: a single array (.npy), not a .npz; {_PRIOR_EXPECTED}")
    with npz:
        missing = [k for k in ("observations", "actions") if k not in npz.files]
        if missing:
            lacks = " and ".join(map(repr, missing))
            raise _UsageError(
                f"{flag}: it holds the arrays {npz.files}, without {lacks}; {_PRIOR_EXPECTED}"
            )
        try:
            return npz["observations"], npz["actions"]
        except Exception as exc:  # an object array (pickle refused), a damaged member
            raise _UsageError(
                f"{flag}: its arrays cannot be read ({type(exc).__name__}: {_one_line(exc)}); "
                f"{_PRIOR_EXPECTED}"
            ) from None


def _cmd_teach(args: argparse.Namespace) -> int:
    import gymnasium as gym

    from torchcbl.benchmark import _import
    from torchcbl.errors import SessionWriteError
    from torchcbl.teaching import (
        ConfidentTeacher,
        TeachingConfig,
        TeachingInterrupted,
    )

    package, env_id, human_module, settings, setup_factory = _TEACH[args.domain]
    run_dir = Path(args.run_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise _UsageError(f"--run-dir {run_dir} is a file; expected a session directory")
    if args.map is not None and args.domain != "corridor":
        raise _UsageError(
            "--map applies only to teach corridor (the driving road is SUMO's; choose its "
            "traffic with --scenario)"
        )
    if args.scenario is not None and args.domain != "driving":
        raise _UsageError(
            "--scenario applies only to teach driving (the corridor's course is chosen with --map)"
        )
    map_kwarg = None
    given_map = None  # with --resume: it must be the session's own map (checked below)
    if args.map is not None:  # a map of one's own, kept with the session by name or full path
        from corridor.maps import available_maps, load_map

        try:
            given_map = load_map(args.map)
        except ValueError as exc:
            raise _UsageError(f"--map: {exc}") from None
        shipped = args.map in available_maps()
        map_kwarg = args.map if shipped else str(Path(args.map).resolve())
    # a shipped scenario's name, or a TrafficScenario of one's own (the session keeps it whole)
    scenario_kwarg = None if args.scenario is None else _scenario_option(args.scenario)
    if args.resume and args.prior_demonstrations is not None:
        raise _UsageError(
            "--prior-demonstrations: a resumed session keeps the prior demonstrations it started "
            "from (prior.npz in its directory); leave --prior-demonstrations out with --resume"
        )
    if args.resume and args.skip_noninteractive:
        raise _UsageError(
            "--skip-noninteractive starts a new session without its non-interactive phase; a "
            "resumed session keeps the phase it is in: leave it out with --resume"
        )
    if args.resume:
        _session_domain(
            run_dir, args.domain, teach=True
        )  # a session of this domain, or a one-line error
        _session_map_exists(run_dir, args.domain)
        _refuse_a_done_session(run_dir, args.domain)  # before the session is opened
    else:  # the store's rule for a new session's folder, said before anything is made
        from torchcbl.errors import IncompatibleRunDirError
        from torchcbl.session import _check_new_session_dir

        try:
            _check_new_session_dir(
                run_dir,
                name="--run-dir",
                resume="Add --resume to continue it",
                remove=f"rm -r {shlex.quote(str(run_dir))}",
            )
        except IncompatibleRunDirError as exc:
            raise _UsageError(_one_line(exc)) from None
        _output_dir(run_dir, "--run-dir")
    prior = None  # read after the run directory's checks: a file that may be large
    if args.prior_demonstrations is not None:
        prior = _read_prior_demonstrations(Path(args.prior_demonstrations))
    importlib.import_module(package)  # registers the env id
    human = importlib.import_module(human_module)
    env_kwargs, rule, make_model = _import(setup_factory)()
    if map_kwarg is not None:
        env_kwargs = {**env_kwargs, "corridor_map": map_kwarg}
    if scenario_kwarg is not None:
        env_kwargs = {**env_kwargs, "scenario": scenario_kwarg}
    if args.resume:  # the env the session was taught in, whatever teach gives a new one today
        env_kwargs = _resume_env_kwargs(run_dir, args.domain)
        if scenario_kwarg is not None:  # given again: it must be the session's own traffic
            _check_session_traffic(run_dir, env_kwargs, args.scenario, scenario_kwarg)
        if given_map is not None:  # given again: it must be the session's own map
            _check_session_map_given(run_dir, env_kwargs, args.map, given_map)
    teacher = human.make_teacher(title=f"torchcbl teach {args.domain}")
    from torchcbl.human import TerminalTeacher

    # q typed while the agent drives on its own stops the run after the step under way (a
    # no-op unless the keys come from a terminal)
    check_quit = teacher.check_quit if isinstance(teacher, TerminalTeacher) else None
    env = gym.make(env_id, **env_kwargs)

    def status(record: Any = None) -> None:  # after each step, and before the first
        rate = ct.autonomy_rate
        acc = ct.windowed_accuracy
        teacher.set_status(
            f"step {ct.n_steps} | phase {ct.phase} | demonstrations {ct.n_demonstrations}"
            f" | prediction accuracy {'-' if acc is None else f'{100 * acc:.0f}%'}"
            f" | autonomy {'-' if rate is None else f'{100 * rate:.0f}%'}"
        )
        if record is not None and check_quit is not None:  # the step is logged whole by now
            check_quit()

    if args.resume:
        from torchcbl.errors import IncompatibleRunDirError, SessionLockedError

        said: list[warnings.WarningMessage] = []
        try:  # (a session another process is teaching, a damaged log: as evaluate says them)
            # its warnings (another simulator release than the last writer's, steps fewer than
            # writer.lock says were committed) each one line below, not Python's two; the
            # filters in force kept (a library's DeprecationWarning stays unsaid, -W error raises)
            with warnings.catch_warnings(record=True) as said:
                ct = ConfidentTeacher.resume(
                    run_dir,
                    env,
                    teacher,
                    progress=False,
                    on_step=status,
                    keep_checkpoints=_kept(args.keep_checkpoints, "as_before"),
                )
        except SessionLockedError as exc:  # the library's words are for Python: say the CLI's
            env.close()
            raise _UsageError(
                f"{run_dir} is being taught by another writer ({exc.holder}): one writer per "
                "session. Stop that teach (q or Ctrl-C in its terminal) or end that process, "
                "then run this again; reading it meanwhile works (torchcbl evaluate)."
            ) from None
        except IncompatibleRunDirError as exc:
            env.close()
            raise _UsageError(_one_line(exc)) from None
        finally:
            for w in said:
                print(f"torchcbl teach: warning: {_one_line(w.message)}", file=sys.stderr)
        if isinstance(teacher, TerminalTeacher):  # "decision #N" goes on from the session's
            # answered requests (read from its log, which stays as it is)
            teacher.n_decisions = sum(r.teacher_action is not None for r in ct.records)
    else:
        config = TeachingConfig(noninteractive=not args.skip_noninteractive, **settings)
        try:
            ct = ConfidentTeacher(
                env,
                teacher,
                model=make_model(seed=args.seed),
                prior_demonstrations=prior,
                rule=rule,
                config=config,
                run_dir=run_dir,
                seed=args.seed,
                progress=False,
                on_step=status,
                keep_checkpoints=_kept(args.keep_checkpoints, DEFAULT_KEEP_CHECKPOINTS),
            )
        except (ValueError, TypeError) as exc:
            env.close()
            if prior is not None and str(exc).startswith("prior_demonstrations:"):
                what = str(exc).removeprefix("prior_demonstrations:")
                raise _UsageError(
                    f"--prior-demonstrations {args.prior_demonstrations}: {_one_line(what)}"
                ) from None
            raise
    # --resume asks for more: the session's own budgets (the driving protocol's 650
    # demonstrations) are lifted for this call, else a finished session could never go on
    lifted = {"max_demonstrations": None, "max_episodes": None} if args.resume else {}
    status()  # a resumed session's counts from its first request on
    if args.resume:  # before the agent drives: it may go on alone for all of --steps
        print(
            f"Resuming the session in {run_dir} at step {ct.n_steps} ({ct.n_demonstrations} "
            f"demonstrations, phase {ct.phase}), in a new episode: {_phase_text(ct)}; "
            f"{args.steps} more steps at most.",
            flush=True,
        )
    go_on = f"continue with: torchcbl teach {args.domain} --run-dir {_shell(run_dir)} --resume"
    try:
        try:
            ct.run(max_steps=ct.n_steps + args.steps, **lifted)
        except TeachingInterrupted as exc:  # q (at a request or between), Ctrl-C at one, EOF
            ended = str(exc).endswith("input closed")  # TerminalTeacher's words for it
            print(
                "\nStopped: the input ended, no key left to read."
                if ended
                else "\nStopped by the teacher."
            )
        except KeyboardInterrupt:  # Ctrl-C between two requests (the agent acting on its own)
            print("\nStopped by the teacher (Ctrl-C).")
        finally:
            try:
                ct.close()
            finally:
                env.close()
    except SessionWriteError as exc:  # the disk filled up: what was recorded is kept
        print(
            f"torchcbl teach: error: {_one_line(exc)} Saved in {run_dir}: {_saved(ct)}; "
            f"free space, then {go_on}",
            file=sys.stderr,
        )
        return 1
    why = _STOP_REASONS.get(ct.stop_reason or "", "")
    from torchcbl.session import _STREAK_DONE

    if ct.stop_reason in _STREAK_DONE:  # done: a --resume of it would have nothing to teach
        go_on = f"evaluate it with: torchcbl evaluate {_shell(run_dir)}"
    print(f"{_saved(ct)} saved in {run_dir}" + (f" ({why})" if why else "") + f"; {go_on}")
    return 0


def _phase_text(ct: Any) -> str:
    """What the agent of ``ct`` (a ConfidentTeacher) does in the phase it is in: in the
    non-interactive phase it asks at every step until its accuracy window reaches the
    target, in confident execution it acts on its own where it is sure."""
    confident = "acts on its own where it is sure and asks you where it is not"
    if ct.phase != "noninteractive":
        return f"the agent {confident}"
    target = ct.config.target_accuracy
    if target is None:  # (a session of Python's: teach always sets one)
        return (
            "the agent asks you at every step (this session's non-interactive phase has no "
            "accuracy target, so it does not end)"
        )
    return (
        "the agent asks you at every step until its prediction accuracy over your last "
        f"{ct.config.accuracy_window} demonstrations reaches {100 * target:g}%, then {confident}"
    )


def _saved(ct: Any) -> str:
    """ "N demonstrations over M steps", in the singular where a count is 1."""
    d, n = ct.n_demonstrations, ct.n_steps
    return f"{_counted(d, 'demonstration')} over {_counted(n, 'step')}"


_STOP_REASONS = {
    "max_demonstrations": "the session's demonstration budget is reached; --resume goes past it",
    "max_steps": "--steps done",
    "max_episodes": "the session's episode budget is reached; --resume goes past it",
    "autonomous_steps": "the agent drove on its own long enough: teaching is done",
    "autonomous_episodes": "the agent drove its episodes on its own: teaching is done",
}


def _refuse_a_done_session(run_dir: Path, domain: str) -> None:
    """Refuse ``teach --resume`` of a session that had met its streak stop (``describe``'s
    ``streak_met``, counted as a resume counts it: a resume would take no step), read-only,
    before it is opened as a writer, so that the refused command changes no file of it. The
    budgets are not asked: ``--resume`` lifts them (it asks for more); a streak cannot be
    lifted, or it would never end. A session that cannot be read, or that a writer holds, is
    left to the resume to say so."""
    done = _done_text(run_dir, domain)
    if done is not None:
        raise _UsageError(f"--resume: the session in {run_dir} is done: {done}")


def _done_text(run_dir: Path, domain: str) -> str | None:
    """Where the session in ``run_dir`` (of ``domain``) is done (see
    :func:`_refuse_a_done_session`): the streak it met, and the commands that go on from it
    (evaluate it, or teach on from its demonstrations in a new session); None where it is not
    done, cannot be read, or a writer holds it."""
    from torchcbl.session import (
        _STREAK_DONE,
        CorruptSessionError,
        IncompatibleRunDirError,
        describe,
    )

    try:
        with warnings.catch_warnings():  # what the readers warn of, the resume says again
            warnings.simplefilter("ignore")
            summary = describe(run_dir)
    except (IncompatibleRunDirError, CorruptSessionError, OSError):
        return None  # the resume says what is wrong with it, as it always did
    if summary.streak_met is None or summary.writer_running is True:
        return None
    field, says = _STREAK_DONE[summary.streak_met]
    stop = summary.stops[field]
    return (
        f"{says.format(stop)} ({field}={stop}), so there is nothing to resume; evaluate it "
        f"(torchcbl evaluate {_shell(run_dir)}), or teach on from its demonstrations "
        f"in a new session (torchcbl teach {domain} --run-dir NEW_DIR "
        f"--prior-demonstrations {_shell(run_dir)})"
    )


# The benchmark's environments: each domain ships its EnvSpec (teacher, budgets, score) in a
# ``benchmark`` module, imported here lazily.
_BENCH_ENVS = {"corridor": "corridor.benchmark", "driving": "sumo_scenarios.benchmark"}


def _cwd_hint(exc: BaseException) -> str:
    """For a module not found that is a file or package of the current directory: that the
    torchcbl command (a console script, unlike ``python -m`` or a script) does not import from
    there, and what to do; else ""."""
    name = getattr(exc, "name", None) if isinstance(exc, ModuleNotFoundError) else None
    if not name:
        return ""
    top, here = name.partition(".")[0], Path.cwd()
    found = next((f for f in (f"{top}.py", f"{top}/") if (here / f.rstrip("/")).exists()), None)
    if found is None:
        return ""
    try:  # imported from the path after all (PYTHONPATH given): a module inside it is missing
        if importlib.util.find_spec(top) is not None:
            return ""
    except (ImportError, ValueError):
        pass
    return (
        f" ({found} is in the current directory, which the torchcbl command does not import "
        "from: run it as PYTHONPATH=$PWD torchcbl ..., or install your package)"
    )


def _check_strategy(spec: Any) -> None:
    """A one-line error unless ``spec`` (a --strategies import path) gives a strategy: the
    class imports, is made with the --strategy-param given for it and has the
    methods :class:`~torchcbl.teaching.ConfidentTeacher` calls (``to_config`` is optional, as
    for the loop: a strategy without it is stored as custom)."""
    from torchcbl.teaching import _STRATEGY_METHODS, _pick_strategy

    try:
        strategy = spec.build(seed=0)
    except ImportError as exc:
        text = _one_line(exc) + _cwd_hint(exc)
        if text.startswith("cannot import"):  # it names the path and what it expected
            raise _UsageError(f"{text} (--strategies)") from None
        raise _UsageError(
            f"--strategies {spec.name}: cannot import it ({text}); expected module:Class of a "
            "strategy, or a shipped name"
        ) from None
    except Exception as exc:  # the user's class: whatever it raises, it is not usable here
        text = _one_line(exc)
        params = (  # a call the signature refused (a parameter missing, say), not its own error
            f": give its parameters with --strategy-param {spec.name}.KEY=VALUE (in Python, "
            "StrategySpec(name, params) with torchcbl.benchmark.run_benchmark)"
            if isinstance(exc, TypeError)
            else ""
        )
        raise _UsageError(
            f"--strategies {spec.name}: cannot make it ({type(exc).__name__}: {text}); expected "
            f"module:Class of a strategy, or a shipped name{params}"
        ) from None
    try:  # the loop's own check
        _pick_strategy(None, strategy)
    except TypeError as exc:
        # named by its type: the loop's message shows the object's repr (a memory address)
        missing = [n for n in _STRATEGY_METHODS if not callable(getattr(strategy, n, None))]
        why = (
            f"it has no {', '.join(f'{n}()' for n in missing)} (a torchcbl.strategies.Strategy "
            f"has the methods {', '.join(_STRATEGY_METHODS)}); see the protocol in "
            "torchcbl.strategies (an episode_start that does nothing is "
            "`def episode_start(self): pass`)"
            if missing and not isinstance(strategy, type)
            else _one_line(exc).removeprefix("strategy: ")
        )
        raise _UsageError(
            f"--strategies {spec.name}: {type(strategy).__name__} is not a strategy: {why}"
        ) from None


def _json_spelling(text: str) -> str | None:
    """The JSON spelling of a value written as Python writes it (``False``, ``None``, ``.5``,
    ``1_0``); None for text that reads as no such value (a string)."""
    words = {"True": "true", "False": "false", "None": "null"}
    if text.strip() in words:
        return words[text.strip()]
    for kind in (int, float):
        try:
            return json.dumps(kind(text))
        except ValueError:
            pass
    return None


def _strategy_params(
    given: list[str], names: list[str], option: str = "--strategy-param"
) -> dict[str, dict[str, Any]]:
    """The --strategy-param (or --strategy-teaching) S.KEY=VALUE options as {strategy: {key:
    value}}: a value is read as JSON (a number, true, null, a list) where it is JSON, else as
    the string given."""
    params: dict[str, dict[str, Any]] = {}
    example = (
        "cba.noninteractive=false"
        if option == "--strategy-teaching"
        else "dagger.iteration_steps=20"
    )
    for item in given:
        target, eq, text = item.partition("=")
        name, dot, key = target.rpartition(".")
        if not eq or not dot or not name or not key.isidentifier():
            raise _UsageError(
                f"{option} {item!r}: expected S.KEY=VALUE, a strategy of --strategies, "
                + (
                    "a TeachingConfig field"
                    if option == "--strategy-teaching"
                    else "one of its constructor's keywords"
                )
                + f" and a value (e.g. {example})"
            )
        if name not in names:
            raise _UsageError(
                f"{option} {item}: {name} is not among --strategies ({','.join(names)}); "
                "name the strategy as --strategies does"
            )
        if key in params.setdefault(name, {}):
            raise _UsageError(f"{option}: {name}.{key} given twice; give each once")
        try:
            value = json.loads(text)
        except ValueError:
            value = text
            meant = _json_spelling(text)
            if meant is not None:
                # Python's spelling or a number JSON does not read: a string would reach the
                # constructor ("False" is true), so say how to write the value meant
                raise _UsageError(
                    f"{option} {item}: {text!r} is not a JSON value; write numbers as "
                    "JSON does (0.5, 3, 1e-3) and true / false / null in lower case "
                    f"({name}.{key}={meant}), or a string in double quotes "
                    f"({name}.{key}='\"{text}\"')"
                ) from None
        params[name][key] = value
    return params


def _benchmark_dir(out: Path) -> bool:
    """Whether ``out`` is a directory a benchmark wrote: it has ``cells/``, or (a sweep with
    ``--keep-sessions`` stopped before its first cell finished, which leaves no ``cells/``) it
    holds only ``sessions/``, and that only the sessions of cells, named by their keys (20
    hex digits, ``.stale-N`` for one set aside)."""
    if (out / "cells").is_dir():
        return True
    sessions = out / "sessions"
    if [p.name for p in out.iterdir()] != ["sessions"] or not sessions.is_dir():
        return False
    names = [p.name for p in sessions.iterdir()]
    return bool(names) and all(re.fullmatch(r"[0-9a-f]{20}(\.stale-\d+)?", n) for n in names)


def _cmd_benchmark(args: argparse.Namespace) -> int:
    import dataclasses
    import importlib.util

    from torchcbl import benchmark as bm

    if args.keep_checkpoints is not None and not args.keep_sessions:
        raise _UsageError(
            f"--keep-checkpoints {args.keep_checkpoints} applies only with --keep-sessions (it "
            "says how many checkpoints each kept session keeps); add --keep-sessions, or leave "
            "it out"
        )
    # None: all shipped; "" names none (an error below), as --envs "" names no domain env
    names = [s for s in args.strategies.split(",") if s] if args.strategies is not None else None
    if names is None:
        names = [
            n
            for n in bm.STRATEGY_PATHS
            if importlib.util.find_spec(bm.STRATEGY_PATHS[n].partition(":")[0]) is not None
        ]
    bad = [n for n in names if n not in bm.STRATEGY_PATHS and ":" not in n]
    if bad:
        raise _UsageError(
            f"--strategies: unknown {bad}; expected names from {sorted(bm.STRATEGY_PATHS)} "
            "or import paths module:Class"
        )
    if not names:
        raise _UsageError(
            f"--strategies {args.strategies!r} names no strategy; expected names from "
            f"{sorted(bm.STRATEGY_PATHS)} or import paths module:Class, comma-separated"
        )
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:  # the tables need one row per strategy
        raise _UsageError(
            f"--strategies {args.strategies}: {twice} given more than once; name each strategy once"
        )
    params = _strategy_params(args.strategy_param or [], names)
    teaching = _strategy_params(args.strategy_teaching or [], names, "--strategy-teaching")
    try:
        strategies = [
            bm.StrategySpec(n, params.get(n, {}), teaching=teaching.get(n, {})) for n in names
        ]
    except ValueError as exc:  # a teaching field it does not know, or a value it refuses
        raise _UsageError(f"--strategy-teaching: {_one_line(exc)}") from None
    for spec in strategies:  # a path of one's own: made once now, before anything is written
        if spec.name not in bm.STRATEGY_PATHS:
            _check_strategy(spec)
        elif spec.params:  # a shipped one given parameters: refused now, before the plan line
            try:
                spec.build(seed=0)
            except Exception as exc:
                raise _UsageError(
                    f"--strategy-param: cannot make {spec.name} with {dict(spec.params)} "
                    f"({type(exc).__name__}: {_one_line(exc)}); give keywords its constructor "
                    "takes, with values it accepts"
                ) from None
    env_names = (
        [e for e in args.envs.split(",") if e] if args.envs is not None else list(_BENCH_ENVS)
    )
    bad = [e for e in env_names if e not in _BENCH_ENVS]
    if bad:
        raise _UsageError(f"--envs: unknown {bad}; expected some of {sorted(_BENCH_ENVS)}")
    twice = sorted({e for e in env_names if env_names.count(e) > 1})
    if twice:
        raise _UsageError(f"--envs {args.envs}: {twice} given more than once; name each env once")
    if args.driving_teacher and "driving" in env_names:
        try:
            bm._import(args.driving_teacher)
        except (ValueError, ImportError, TypeError) as exc:  # TypeError: a relative name
            raise _UsageError(
                f"--driving-teacher {args.driving_teacher}: {_one_line(exc)}{_cwd_hint(exc)}"
            ) from None
    envs = []
    for e in env_names:
        spec = importlib.import_module(_BENCH_ENVS[e]).env_spec(quick=args.quick)
        if e == "driving" and args.driving_teacher:
            spec = dataclasses.replace(spec, teacher=args.driving_teacher)
        envs.append(spec)
    gym_only = ("teacher", "score", "budgets", "max_steps", "eval_episodes", "eval_steps")
    given = [f"--{n.replace('_', '-')}" for n in gym_only if getattr(args, n) is not None]
    if args.driving_teacher and "driving" not in env_names:
        raise _UsageError("--driving-teacher applies only with driving in --envs")
    if given and not args.gym_env:
        raise _UsageError(
            f"{', '.join(given)} apply only to --gym-env (the envs of --envs bring their own); "
            "add --gym-env module:Id, or leave them out"
        )
    if args.gym_env:
        import gymnasium as gym

        if not args.teacher:
            raise _UsageError(
                "--gym-env needs --teacher module:factory (the teacher's import path)"
            )
        module, _, env_id = args.gym_env.rpartition(":")  # "module:Id" imports module first,
        try:  # as gymnasium.make does
            if module:
                importlib.import_module(module)
            gym.spec(env_id)
        except ImportError as exc:
            raise _UsageError(
                f"--gym-env {args.gym_env}: {_one_line(exc)}{_cwd_hint(exc)}"
            ) from None
        except gym.error.Error as exc:  # not registered (after importing module, if given)
            if module:
                hint = (
                    f"{module} was imported but registers no such id; give the id its "
                    "register(id=...) call gives"
                )
            elif isinstance(exc, (gym.error.VersionNotFound, gym.error.DeprecatedEnv)) or (
                "did you mean" in str(exc).lower()
            ):  # gymnasium knows the name: another version or spelling, which it names
                hint = "give an id that gymnasium registers"
            else:  # the id alone: only gymnasium's own and those of packages already imported
                guess = env_id.partition("/")[0] if "/" in env_id else "mymodule"
                hint = (
                    "if a module of yours registers it, name that module first: "
                    f"--gym-env {guess}:{env_id} (module:Id, as gymnasium.make reads it)"
                )
            text = _one_line(exc).rstrip(".")
            raise _UsageError(f"--gym-env {args.gym_env}: {text}; {hint}") from None
        score = args.score or "torchcbl.benchmark:success_rate"
        for option, path in (("--teacher", args.teacher), ("--score", score)):
            try:  # before anything runs or is printed
                bm._import(path)
            except (ValueError, ImportError, TypeError) as exc:  # TypeError: a relative name
                raise _UsageError(f"{option} {path}: {_one_line(exc)}{_cwd_hint(exc)}") from None
        budgets, max_steps = args.budgets or (10, 20, 40, 80), args.max_steps or 1000
        above = [b for b in budgets if b > max_steps]
        if above:  # as EnvSpec refuses them, in the options' names
            raise _UsageError(
                f"--budgets {','.join(map(str, budgets))}"
                + ("" if args.budgets else " (the default)")
                + f": {above} above --max-steps {max_steps}"
                + ("" if args.max_steps else " (the default)")
                + "; a cell takes at most one label per step, so no strategy could reach them; "
                "raise --max-steps or give --budgets up to it"
            )
        try:
            envs.append(
                bm.EnvSpec(
                    name=args.gym_env,
                    env_id=args.gym_env,
                    teacher=args.teacher,
                    budgets=budgets,
                    max_steps=max_steps,
                    score=score,
                    # 10 episodes unless --eval-steps alone says how long an evaluation is
                    eval_episodes=args.eval_episodes or (None if args.eval_steps else 10),
                    eval_steps=args.eval_steps,
                )
            )
        except ValueError as exc:
            raise _UsageError(f"--gym-env: {exc}") from None
    if not envs:
        raise _UsageError("no environment: give --envs and/or --gym-env")
    _check_importable([m for e in env_names for m in _DOMAIN_NEEDS[e]] + ["matplotlib"])
    seeds = list(range(args.seeds if args.seeds is not None else (3 if args.quick else 10)))
    out = _output_dir(
        Path(args.out or ("runs/benchmark-quick" if args.quick else "runs/benchmark")), "--out"
    )
    if out.is_dir() and any(out.iterdir()) and not _benchmark_dir(out):
        # a benchmark writes results.json, cells/ and its plot here: never over another run
        raise _UsageError(
            f"--out {out} holds files and is not a benchmark's directory (no cells/); choose a "
            "new or empty directory, or one an earlier benchmark wrote (its finished cells are "
            "reused)"
        )
    n_cells = len(strategies) * len(envs) * len(seeds)
    _print_if_read(
        f"benchmark: {len(strategies)} strategies x {len(envs)} envs x {len(seeds)} seeds = "
        f"{n_cells} cells into {out} ("
        + (
            f"Ray at {args.ray_address}"
            if args.ray_address
            else "local Ray"
            if args.ray
            else f"{args.workers} processes"
            if args.workers > 1
            else "in this process"  # run_benchmark runs workers=1 in-process
        )
        + ")",
    )
    count = 0
    bare: list[str] = []  # cached cells without a session, with --keep-sessions
    teacher_ended: dict[str, list[int | None]] = {}  # per env: each cell's finished episodes

    def on_cell(cell: dict, cached: bool) -> None:
        nonlocal count
        count += 1
        teacher_ended.setdefault(cell["env"], []).append(cell.get("teacher_episodes_ended"))
        if args.keep_sessions and cached and not (out / "sessions" / cell["key"]).is_dir():
            bare.append(cell["key"])
        last = cell["curve"][-1] if cell["curve"] else {"labels": 0, "performance": float("nan")}
        _print_if_read(
            f"[{count}/{n_cells}] {cell['env']:>9} {cell['strategy']:>10} seed {cell['seed']}: "
            + ("cached" if cached else f"{cell['wall_s']:.0f} s")
            + f", {last['labels']} labels -> performance {last['performance']:.2f}",
        )

    t0, c0 = time.perf_counter(), os.times()
    try:
        with warnings.catch_warnings():  # said in one line below
            warnings.filterwarnings("ignore", message="run_benchmark: keep_sessions: ")
            summary = bm.run_benchmark(
                strategies,
                envs,
                seeds,
                out,
                workers=args.workers,
                use_ray=bool(args.ray or args.ray_address),
                ray_address=args.ray_address,
                on_cell=on_cell,
                keep_sessions=args.keep_sessions,
                keep_checkpoints=_kept(args.keep_checkpoints, DEFAULT_KEEP_CHECKPOINTS),
            )
    except (RuntimeError, ValueError, ImportError) as exc:
        raise _UsageError(_missing_dependency(exc) or str(exc) + _cwd_hint(exc)) from None
    except KeyboardInterrupt as exc:  # main says it in its one line, with how to go on
        exc.note = (  # type: ignore[attr-defined]
            f" ({_counted(count, 'finished cell')} kept in {out / 'cells'}: go on with the same "
            "command)"
            if count
            else " (no cell had finished: the same command starts the sweep again)"
        )
        raise
    c1 = os.times()
    cpu = (c1.user - c0.user) + (c1.system - c0.system)
    cpu += (c1.children_user - c0.children_user) + (c1.children_system - c0.children_system)
    _print_if_read()
    _print_if_read(bm.format_table(summary))
    _print_if_read(  # what the figures are: the table alone does not say
        f"\nEach figure: mean ± sd over the {_counted(len(seeds), 'seed')} of its row (sample "
        'sd, n − 1; "(n = 1)": one seed, no spread; differences between rows: below); '
        "≥: a lower bound, (k/n) of the seeds never reached 95 % of the teacher and count at "
        "their last labels; perf. "
        "at a budget: the model of the last snapshot at or below it, (k/n reached): only k "
        "seeds held that many labels; (rate), auditor ≠ "
        "teacher: means over the seeds that have one."
    )
    _print_if_read()
    _print_if_read(bm.format_paired(summary))
    for env_name, rows in summary["table"].items():
        scores = [r["teacher_performance"]["mean"] for r in rows.values()]
        if scores and all(s is not None and s <= 0 for s in scores):
            score = summary["envs"][env_name]["score"]
            eval_steps = summary["envs"][env_name].get("eval_steps")
            # (None: a cached cell of an earlier version, which did not count them)
            ended = teacher_ended.get(env_name, [None])
            success = score == "torchcbl.benchmark:success_rate" and max(scores) == 0
            if success and eval_steps is not None and all(e == 0 for e in ended):
                why = (
                    "no evaluation episode of the teacher ended within its "
                    f"{eval_steps} steps (eval_steps, --eval-steps), and success_rate scores "
                    'the episodes that end, so every performance is 0 and "labels to 95 %" is '
                    "undefined; give --eval-steps long enough for episodes to end (or leave "
                    "it out and give --eval-episodes), or pass --score with a score that needs no "
                    "finished episode"
                )
            elif success:
                why = (
                    "the score measures nothing there (success_rate needs an env that sets "
                    'info["is_success"] where an episode ends), so every performance is 0 and '
                    '"labels to 95 %" is undefined; pass --score with a score for this env'
                )
            else:
                why = (
                    f'"labels to 95 %" needs a teacher score above 0 (95 % of it is the '
                    f"target), so it is undefined there; give --score one that is positive for "
                    f"the teacher and higher when better (a return shifted by its worst value, "
                    f"say), not {score}"
                )
            print(
                f"\nwarning: the teacher scores {max(scores):g} on {env_name}: {why}",
                file=sys.stderr,
            )
    if bare:
        print(
            f"\nwarning: --keep-sessions: {len(bare)} cached cell"
            f"{' has' if len(bare) == 1 else 's have'} no session in {out / 'sessions'} "
            f"(computed without --keep-sessions), e.g. {bare[0]}; a cached cell is not computed "
            f"again: delete its {out / 'cells'}/<key>.json to compute it again with its session",
            file=sys.stderr,
        )
    _print_if_read(
        f"\nwall {time.perf_counter() - t0:.0f} s, CPU {cpu:.0f} s (this process and its "
        f"workers); results in {out / 'results.json'}, plot {out / 'learning_curves.png'}"
        + (f", teaching sessions in {out / 'sessions'}" if args.keep_sessions else "")
    )
    return 0


def _version() -> str:
    """``torchcbl --version``: torchcbl's version with torch's (read from its installed
    metadata, so the command does not import torch for it) and Python's."""
    import importlib.metadata
    import platform

    from torchcbl import __version__

    try:
        torch = importlib.metadata.version("torch")
    except importlib.metadata.PackageNotFoundError:
        torch = "not installed"
    return f"torchcbl {__version__} (torch {torch}, Python {platform.python_version()})"


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="torchcbl",
        description="Confidence-based learning from demonstration with Gaussian mixture sets "
        "(Chernova & Veloso, AAMAS 2007).",
    )
    parser.add_argument(
        "--version",
        action="version",
        version=_version(),
        help="print torchcbl's version (with torch's and Python's) and exit",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser(
        "reproduce",
        help="reproduce the paper's experiments (quick by default)",
        description="Run the corridor (Section 5.1) and/or driving (Section 5.2) experiment "
        "over several seeds and write results.json, figures and a summary table into --out.",
    )
    p.add_argument(
        "domain",
        nargs="?",
        default="all",
        choices=["all", *_DOMAINS],
        help="which experiment: corridor, driving or all (default all)",
    )
    p.add_argument("--full", action="store_true", help="the paper's full sizes (slow)")
    p.add_argument(
        "--seeds",
        type=_int_at_least(
            1, at_most=_MAX_SEEDS, hint="leave --seeds out for the experiment's own"
        ),
        default=None,
        metavar="N",
        help=f"run seeds 0 .. N-1, N at most {_MAX_SEEDS} (default: the experiment's own: 10 "
        "for each; with --full 30 corridor, 20 driving)",
    )
    p.add_argument(
        "--workers",
        type=_positive_int,
        default=2,
        metavar="N",
        help="parallel processes (default 2)",
    )
    p.add_argument(
        "--out",
        default="runs/reproduce",
        metavar="DIR",
        help="output directory (default runs/reproduce; never overwritten: -2, -3, ... added)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the stopped run in --out (the same domain, --full and --seeds): its "
        "finished seeds are kept, a seed stopped part-way runs again",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_reproduce)

    p = sub.add_parser(
        "evaluate",
        help="evaluate a saved policy (a teaching session directory)",
        description="Load the latest model of a teaching session and run it greedily, never "
        "asking; print a JSON report (corridor: circuits and wall contacts; driving: collision "
        'rate and lane shares, "lanes", right shoulder first, left shoulder last, as '
        '"lane_names" beside it lists them, and the road driven: "scenario", "eval_segment" '
        'and "held_out"). A driving session is driven on road it was not taught on: its '
        "traffic's held-out twin, the same traffic on the next base seed (train's is eval, as "
        "the reproduction evaluates; light's light-held-out), whose road segments no episode "
        "of the taught traffic drives. --scenario or --seed that drive road the session was "
        "taught on are driven, with a one-line warning that the figures are not held out "
        '("held_out": false). Road its prior demonstrations were taught on counts as taught; '
        'where that cannot be told, "held_out" is null, with a one-line warning saying why.',
        epilog=_EVALUATE_EPILOG,
    )
    p.add_argument(
        "run_dir",
        metavar="SESSION_DIR",
        help="a teaching session directory (holding config.json), e.g. "
        "runs/reproduce/corridor/sessions/seed0 or the --run-dir of torchcbl teach",
    )
    p.add_argument(
        "--domain",
        choices=list(_DOMAINS),
        default=None,
        help="the session's domain (default: read from the session; if given it must agree)",
    )
    p.add_argument(
        "--steps",
        type=_positive_int,
        default=1000,
        metavar="N",
        help="timesteps to run (default 1000)",
    )
    p.add_argument(
        "--seed",
        type=_seed,
        default=None,
        metavar="S",
        help="seed of the first reset (corridor: the env's noise, default 0; driving: which "
        "road segment of the traffic driven, default: for a reproduction's session "
        "(RUN_DIR/seed_<k>/sessions/arm_a) the segment the run evaluated seed k on, "
        "eval_segment + k as its seed_result.json says, else 0)",
    )
    p.add_argument(
        "--scenario",
        default=None,
        metavar="NAME|FILE.json",
        help="driving: drive this traffic instead, a shipped scenario's name (train, eval, "
        "light) or a JSON file of TrafficScenario fields, as teach --scenario takes (default: "
        "the held-out twin of the session's own traffic, the same traffic on the next base "
        "seed: eval for train, as the reproduction evaluates, light-held-out for light, "
        "NAME-held-out for a file's)",
    )
    p.set_defaults(func=_cmd_evaluate)

    p = sub.add_parser(
        "replay",
        help="replay a recorded SUMO episode (or a driving session's) to GIF, FCD XML and "
        "a .sumocfg",
        description="Re-simulate a recorded driving episode bit-identically and export it.",
    )
    p.add_argument(
        "episodes",
        metavar="EPISODES.json|SESSION_DIR",
        help="an episodes.json written by the driving experiment "
        "(runs/reproduce/driving/seed_<k>/episodes.json), or a driving teaching session's "
        "directory (torchcbl teach driving --run-dir), whose episodes are replayed and checked "
        "against its log",
    )
    which = p.add_mutually_exclusive_group()
    which.add_argument(
        "--episode",
        type=_nonnegative_int,
        default=0,
        metavar="N",
        help="index of the episode (default 0; see --list)",
    )
    which.add_argument(
        "--label",
        default=None,
        metavar="TEXT",
        help="the first episode whose label contains TEXT (instead of --episode)",
    )
    p.add_argument(
        "--list", action="store_true", help="list the recorded episodes and stop (needs no SUMO)"
    )
    p.add_argument(
        "--gif",
        default=None,
        metavar="OUT.gif",
        help="GIF output path (default beside the JSON or the session directory: "
        "EPISODES-N.gif, SESSION_DIR-N.gif)",
    )
    p.add_argument(
        "--fcd",
        default=None,
        metavar="OUT.xml",
        help="SUMO FCD XML output path (default beside the JSON or the session directory: "
        "EPISODES-N.fcd.xml, SESSION_DIR-N.fcd.xml; a name ending in .gz is gzipped); a "
        ".sumocfg that opens it in sumo-gui is written beside it",
    )
    p.add_argument(
        "--every",
        type=_positive_int,
        default=1,
        metavar="N",
        help="GIF: draw every N-th timestep (default 1)",
    )
    p.add_argument(
        "--max-frames",
        type=_positive_int,
        default=None,
        metavar="N",
        help="GIF frames at most (default: the whole episode)",
    )
    p.set_defaults(func=_cmd_replay)

    p = sub.add_parser(
        "plot",
        help="redraw the figures of a run directory",
        description="Read RUN_DIR/results.json and write its figures as PNG (the corridor's "
        "also read the first seed's teaching session, RUN_DIR/sessions/seed<k>).",
    )
    p.add_argument(
        "run_dir",
        metavar="RUN_DIR",
        help="a run directory written by torchcbl reproduce (holding results.json), e.g. "
        "runs/reproduce/corridor",
    )
    p.set_defaults(func=_cmd_plot)

    p = sub.add_parser(
        "show",
        help="say what a teaching session directory holds (or list the sessions in a folder)",
        description="Print what a teaching session holds, read-only (safe while its writer "
        "runs, and on a read-only copy): its env, strategy and model, steps, episodes, labels "
        "(demonstrations, corrections), requests (steps the teacher was asked) and autonomous "
        "steps, requests per episode, the newest checkpoint and those on disk (with the "
        "retention its last writer kept, and how an earlier stage is rebuilt), the stops its "
        "config.json keeps and whether it is done (its log ends on the streak it stops at, "
        "counted as a resume counts it: a resume takes no step), its writers "
        "(torch and numpy "
        "versions, threads, device) and whether a writer holds it now or was killed. Given a "
        "folder that holds sessions (a reproduction's run directory, a benchmark's OUT/sessions), "
        'one line per session (a done one ending "; done: ..."), and the folders below it this '
        "user may not list (whose sessions are not counted). A path that holds no session, or "
        "a session that cannot be read: errors go to stderr as one line (exit 2), also with "
        "--json.",
    )
    p.add_argument(
        "run_dir",
        metavar="SESSION_DIR|DIR",
        help="a teaching session directory (holding config.json), e.g. "
        "runs/reproduce/corridor/sessions/seed0, the --run-dir of torchcbl teach or a "
        "benchmark's OUT/sessions/<key>; or a folder holding sessions up to 5 levels below, "
        "each listed in one line",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object instead (the fields of torchcbl.session.SessionSummary; "
        'for a folder {"folder": ..., "sessions": [...]}, a session that cannot be read as '
        '{"run_dir": ..., "error": ...})',
    )
    p.set_defaults(func=_cmd_show)

    p = sub.add_parser(
        "teach",
        help="teach an agent yourself from the terminal",
        description="You are the teacher: the agent shows you its situation and asks for an "
        "action (one key) whenever it is unsure; every demonstration is saved to --run-dir. "
        "q stops the session at a request or, on a terminal, while the agent drives on its "
        "own (after the step under way); Ctrl-C stops it at once; "
        "--resume goes on from where it stopped.",
        epilog=_teach_epilog(),
    )
    p.add_argument("domain", choices=list(_DOMAINS), help="which agent: corridor or driving")
    p.add_argument(
        "--run-dir",
        default="runs/teach",
        metavar="DIR",
        help="session directory (default runs/teach)",
    )
    p.add_argument("--resume", action="store_true", help="continue the session in --run-dir")
    p.add_argument(
        "--seed",
        type=_seed,
        default=0,
        metavar="S",
        help="session seed: seeds the first reset and the model's fits (default 0; "
        "with --resume the session's own seed is kept)",
    )
    p.add_argument(
        "--steps",
        type=_positive_int,
        default=2000,
        metavar="N",
        help="stop after this many more steps (default 2000)",
    )
    p.add_argument(
        "--skip-noninteractive",
        action="store_true",
        help="start directly in confident execution (no teleoperation phase)",
    )
    p.add_argument(
        "--prior-demonstrations",
        default=None,
        metavar="FILE.npz|DIR",
        help="start from demonstrations you already have: a .npz with arrays 'observations' "
        "[N, D] and 'actions' [N], or an earlier session's directory (its training set; the "
        "session records which, so that a driving evaluate counts the road it was taught on "
        "as taught, where a .npz's origin is not known: held_out null); every fit includes "
        "them, the session keeps them, and they do not count as its "
        "demonstrations (the non-interactive phase still asks at every step until its window "
        "is full and its accuracy reaches the target: with a good prior, add "
        "--skip-noninteractive)",
    )
    p.add_argument(
        "--map",
        default=None,
        metavar="NAME|PATH",
        help="corridor: a shipped map's name or a map JSON of your own (default: the "
        "reproduction's figure2); the session keeps it, so --resume (no --map needed; another "
        "map is refused, the same one by another name or path is not) and evaluate drive the "
        "same map (a map file changed after teaching is refused)",
    )
    p.add_argument(
        "--scenario",
        default=None,
        metavar="NAME|FILE.json",
        help="driving: the traffic, a shipped scenario's name (train, the default and the "
        "reproduction's; eval, its held-out twin; light) or a JSON file of TrafficScenario "
        'fields, one object with "seed" (an int >= 0, required), e.g. {"seed": 7, '
        '"mean_spacing_m": [80, 60, 200]}; fields left out take train\'s values (the fields: '
        "README.md, teach driving --scenario). The session keeps it whole, so --resume (no "
        "--scenario needed; another one is refused), evaluate and replay drive the same "
        "traffic",
    )
    p.add_argument(
        "--keep-checkpoints",
        type=_keep_checkpoints,
        default=None,
        metavar="N|all",
        help="keep the newest N checkpoints (one is written per refit; checkpoint 0 is always "
        f"kept) or all of them (default {DEFAULT_KEEP_CHECKPOINTS}; with --resume what the "
        "session kept). An earlier stage's model is rebuilt from the log by "
        "torchcbl.load_model(run_dir, n_demonstrations=k)",
    )
    p.set_defaults(func=_cmd_teach)

    p = sub.add_parser(
        "benchmark",
        help="compare teaching strategies (CE, CBA, BC, DAgger, HG-DAgger, novelty)",
        description="Strategies x environments x seeds with the same teacher and label "
        "budgets; writes OUT/results.json (labels to 95% of the teacher, performance at "
        "budgets, attention) and OUT/learning_curves.png. Finished cells are cached in OUT, "
        "so a rerun (or a killed sweep) continues where it stopped.",
    )
    p.add_argument("--quick", action="store_true", help="small budgets, 3 seeds (minutes)")
    p.add_argument(
        "--strategies",
        default=None,
        metavar="S,..",
        help="comma-separated names or module:Class paths (default: all shipped)",
    )
    p.add_argument(
        "--strategy-param",
        action="append",
        default=None,
        metavar="S.KEY=VALUE",
        help="a keyword argument of strategy S's constructor, VALUE read as JSON where it is "
        "JSON, else as a string (e.g. dagger.iteration_steps=20, confident.max_std=3; for "
        "confident they are the DistanceRule's); repeat for more. Part of each cell's key",
    )
    p.add_argument(
        "--strategy-teaching",
        action="append",
        default=None,
        metavar="S.KEY=VALUE",
        help="a TeachingConfig learning field for strategy S's cells over the env's teaching "
        "settings (e.g. cba.noninteractive=false: CBA without confident execution's "
        "non-interactive phase, as JAIR 2009 publishes it); repeat for more. Part of each "
        "cell's key",
    )
    p.add_argument(
        "--envs",
        default=None,
        metavar="E,..",
        help='comma-separated of corridor,driving (default both, with --gym-env too; "" for '
        "none, e.g. to run --gym-env alone)",
    )
    p.add_argument(
        "--seeds",
        # 0 is refused, as reproduce refuses it (it ran the default 10 seeds, a long sweep)
        type=_int_at_least(
            1,
            at_most=_MAX_SEEDS,
            hint="leave --seeds out for the default: 3 with --quick, else 10",
        ),
        default=None,
        metavar="N",
        help=f"seeds 0..N-1, N at most {_MAX_SEEDS} (default 3 with --quick, else 10)",
    )
    p.add_argument(
        "--workers", type=_positive_int, default=2, metavar="N", help="local processes (default 2)"
    )
    p.add_argument("--ray", action="store_true", help="run the cells on a local Ray")
    p.add_argument(
        "--ray-address", default=None, metavar="ADDR", help="run on this Ray cluster (e.g. auto)"
    )
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="benchmark directory (default runs/benchmark[-quick])",
    )
    p.add_argument(
        "--keep-sessions",
        action="store_true",
        help="also keep each computed cell's teaching session in OUT/sessions/<key> (the key of "
        "its OUT/cells/<key>.json; read it with torchcbl.session.load_records, load_labels, "
        "load_model, or torchcbl evaluate (corridor and driving cells; others in Python with "
        "torchcbl.load_policy)); the figures are the same either way. A cached cell "
        "is not computed again for its session; one that a killed or failed run left is set "
        "aside as <key>.stale-N",
    )
    p.add_argument(
        "--keep-checkpoints",
        type=_keep_checkpoints,
        default=None,
        metavar="N|all",
        help="with --keep-sessions: each session keeps its newest N checkpoints (and checkpoint "
        f"0) or all of them (default {DEFAULT_KEEP_CHECKPOINTS}), as torchcbl teach "
        "--keep-checkpoints; not part of a cell's key, the figures are the same either way",
    )
    p.add_argument(
        "--driving-teacher",
        default=None,
        metavar="MODULE:NAME",
        help="import path of the driving teacher",
    )
    p.add_argument(
        "--gym-env",
        default=None,
        metavar="MODULE:ID",
        help="also benchmark this gymnasium id (module imported first, as gymnasium.make "
        "does), beside the --envs ones: by default corridor and driving, the full sweep; add "
        '--envs "" to run this env alone',
    )
    g = "only with --gym-env: "
    p.add_argument("--teacher", metavar="MODULE:NAME", help=g + "the teacher factory")
    p.add_argument(
        "--score",
        metavar="MODULE:NAME",
        help=g + "the score of an evaluation (default torchcbl.benchmark:success_rate)",
    )
    p.add_argument(
        "--budgets", type=_budgets, metavar="B,..", help=g + "label budgets (default 10,20,40,80)"
    )
    p.add_argument(
        "--max-steps", type=_positive_int, metavar="N", help=g + "step cap (default 1000)"
    )
    p.add_argument(
        "--eval-episodes",
        type=_positive_int,
        metavar="N",
        help=g + "episodes per evaluation (default 10; none when --eval-steps is given alone). "
        "Without --eval-steps, on an env with no step cap (no TimeLimit, none of its own), an "
        "evaluation whose episodes have not ended within 10,000 steps each (--max-steps where "
        "more) stops the sweep",
    )
    p.add_argument(
        "--eval-steps",
        type=_positive_int,
        metavar="N",
        help=g + "steps per evaluation (with --eval-episodes: whichever comes first)",
    )
    p.set_defaults(func=_cmd_benchmark)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``torchcbl`` console script; returns the exit code.

    A usage mistake (a path that is not what the command reads, a number out of range) or a
    missing dependency (the line names the package and how to install it) is one line on
    stderr and exit code 2; Ctrl-C is one line and exit code 130; a write into a pipe whose
    reader has gone (``| head -1``) ends the command quietly with exit code 141 (``benchmark``
    stops printing and finishes its sweep); any other failure is one line and exit code 1 (set
    ``TORCHCBL_TRACEBACK=1`` to see its traceback instead). What the terminal's encoding
    cannot show (a summary's '±' under ``PYTHONIOENCODING=ascii``) is written escaped, as ``\\xb1``.
    """
    restore = _escape_what_the_terminal_cannot_show()
    try:
        return _main(argv)
    finally:
        restore()


def _main(argv: Sequence[str] | None) -> int:
    args = _parser().parse_args(argv)
    prog = f"torchcbl {args.command}"
    try:
        return int(args.func(args) or 0)
    except _UsageError as exc:
        print(f"{prog}: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        more = getattr(exc, "note", "")  # reproduce: how to go on
        print(f"{prog}: interrupted{more}", file=sys.stderr)
        return 130
    except BrokenPipeError as exc:
        if not _stdout_closed():
            return _failure(prog, exc)
        # the reader of our output went away (`torchcbl evaluate DIR | head -1`): stop quietly,
        # as a command killed by SIGPIPE does, and keep the interpreter's own final flush from
        # writing to the closed pipe again
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except Exception as exc:
        missing = _missing_dependency(exc)
        if missing is None or os.environ.get("TORCHCBL_TRACEBACK"):
            return _failure(prog, exc)
        print(f"{prog}: error: {missing}", file=sys.stderr)
        return 2


_TOLERANT = "torchcbl.terminal"  # the error handler below, by the name codecs knows it by


def _write_what_cannot_be_encoded(exc: UnicodeError) -> tuple[str | bytes, int]:
    """The codec error handler of ``_TOLERANT``: a character the terminal's encoding lacks
    ('±', '≠' on an ASCII or latin-1 terminal) is written escaped, as ``\\xb1``; an
    undecodable byte of a file name (read as a surrogate, as Python reads it under such a
    locale) is written as that byte, as Python's own "surrogateescape" writes it."""
    try:
        return codecs.lookup_error("surrogateescape")(exc)
    except UnicodeError:
        return codecs.backslashreplace_errors(exc)


codecs.register_error(_TOLERANT, _write_what_cannot_be_encoded)


def _escape_what_the_terminal_cannot_show() -> Callable[[], None]:
    """Make standard output and error write what their encoding cannot show escaped
    (``_TOLERANT``) where that encoding is not UTF-8: a summary's '±' on an ASCII terminal
    (``PYTHONIOENCODING=ascii``; ``LC_ALL=C`` with ``PYTHONUTF8=0``) raised
    UnicodeEncodeError at the end of a command. Returns the function that puts their error
    handlers back."""
    changed: list[tuple[Any, str]] = []
    for stream in (sys.stdout, sys.stderr):
        encoding = getattr(stream, "encoding", None)
        try:
            utf8 = codecs.lookup(encoding or "utf-8").name == "utf-8"
        except LookupError:
            utf8 = False
        if utf8 or not hasattr(stream, "reconfigure"):
            continue
        try:
            before = stream.errors
            stream.reconfigure(errors=_TOLERANT)
        except (AttributeError, OSError, ValueError):  # closed, or not a text stream of io's
            continue
        changed.append((stream, before))

    def restore() -> None:
        for stream, before in changed:
            try:
                stream.reconfigure(errors=before)
            except (OSError, ValueError):  # closed meanwhile, or its reader went away
                pass

    return restore


def _failure(prog: str, exc: Exception) -> int:
    """One line on stderr for an unexpected failure (exit code 1), or its traceback with
    ``TORCHCBL_TRACEBACK=1``."""
    if os.environ.get("TORCHCBL_TRACEBACK"):
        raise exc
    print(
        f"{prog}: error: {type(exc).__name__}: {_one_line(exc)} "
        "(set TORCHCBL_TRACEBACK=1 to see where)",
        file=sys.stderr,
    )
    return 1


def _stdout_closed() -> bool:
    """True when nothing reads our standard output any more (its pipe's reader has exited)."""
    try:
        import select

        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(ev & select.POLLERR for _, ev in poller.poll(0))
    except (AttributeError, OSError, ValueError):  # no poll (Windows) or no real stdout
        return True


def _print_if_read(*values: object) -> None:
    """``print(*values)`` on standard output, flushed, while something reads it: once its
    reader has gone (a closed pipe: ``torchcbl benchmark ... | head -2``), the rest goes to
    os.devnull and the command goes on, so a sweep still writes the results it is run for."""
    try:
        print(*values, flush=True)
    except BrokenPipeError:
        if not _stdout_closed():
            raise
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)


def _shell(path: Path) -> str:
    """``path`` as a shell word, for a command line the user is told to run (a path with a
    space or a quote in it, quoted)."""
    import shlex

    return shlex.quote(str(path))


if __name__ == "__main__":
    sys.exit(main())
