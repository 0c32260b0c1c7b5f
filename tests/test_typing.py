"""The public API's type hints, as a user's type checker (mypy, pyright) reads them.

The package ships py.typed (tests/test_package.py), so these hints are what a researcher's
editor checks their code against: a hint narrower than what the code takes rejects correct
code, one wider lets a mistake through. mypy is not a dependency, so the hints are read here
with typing's own introspection (get_type_hints, get_overloads) and the source's syntax.
"""

from __future__ import annotations

import ast
import inspect
import types
import typing
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]


def _members(hint: Any) -> list[Any]:
    """The types a hint admits, out of its unions (a generic as its origin class)."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        return [m for a in typing.get_args(hint) for m in _members(a)]
    if origin is not None and origin is not Literal:
        return [origin]
    return [type(None) if hint is None else hint]


def _admits(hint: Any, cls: type) -> bool:
    """Whether a value of class ``cls`` passes ``hint`` (Any passes everything)."""
    return any(m is Any or (isinstance(m, type) and issubclass(cls, m)) for m in _members(hint))


def test_every_public_name_of_torchcbl_is_seen_by_a_type_checker():
    """torchcbl loads its public names lazily (a module __getattr__, so `import torchcbl`
    stays light), and a type checker cannot see through that: `from torchcbl import
    ConfidentTeacher` was Any to mypy and pyright, so nothing a user wrote with it was checked.
    Each name of the export table is imported for type checkers alone (under TYPE_CHECKING),
    from the module the table names, as `X as X` (an explicit re-export: __all__ is built at
    run time, which a checker does not read)."""
    import torchcbl

    tree = ast.parse((ROOT / "torchcbl" / "__init__.py").read_text())
    typed: dict[str, str] = {}
    for node in tree.body:
        test = getattr(node, "test", None)
        if isinstance(node, ast.If) and isinstance(test, ast.Name) and test.id == "TYPE_CHECKING":
            for imp in node.body:
                assert isinstance(imp, ast.ImportFrom) and imp.module, ast.dump(imp)
                for alias in imp.names:
                    assert alias.asname == alias.name, f"{alias.name}: not re-exported"
                    typed[alias.name] = imp.module
    assert typed == torchcbl._EXPORTS


def test_the_lazily_loaded_names_of_torchcbl_strategies_are_seen_by_a_type_checker():
    """torchcbl.strategies loads ConfidenceBasedAutonomy through a module __getattr__ (its
    module imports the package's base class), which a type checker cannot see through:
    `from torchcbl.strategies import ConfidenceBasedAutonomy` was Any to mypy and pyright, so
    a misspelt argument passed. Each name of __all__ that the module does not bind itself is
    imported for type checkers alone (under TYPE_CHECKING) as `X as X` (re-exported), from a
    module that holds the object the package hands out at run time."""
    import importlib

    import torchcbl.strategies as strategies

    tree = ast.parse((ROOT / "torchcbl" / "strategies" / "__init__.py").read_text())
    bound: set[str] = set()
    typed: dict[str, str] = {}
    for node in tree.body:
        test = getattr(node, "test", None)
        if isinstance(node, ast.If) and isinstance(test, ast.Name) and test.id == "TYPE_CHECKING":
            for imp in node.body:
                if isinstance(imp, ast.ImportFrom) and imp.module:
                    typed |= {a.name: imp.module for a in imp.names if a.asname == a.name}
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            bound.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            bound |= {(a.asname or a.name).split(".")[0] for a in node.names}
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            bound |= {t.id for t in targets if isinstance(t, ast.Name)}
    lazy = set(strategies.__all__) - bound
    assert "ConfidenceBasedAutonomy" in lazy  # the check sees the lazy names
    assert lazy <= set(typed), f"lazily loaded, Any to a type checker: {lazy - set(typed)}"
    for name in lazy:
        held = getattr(importlib.import_module(typed[name]), name)
        assert getattr(strategies, name) is held, name


def test_the_fitted_buffers_are_tensors_to_a_type_checker():
    """A GaussianMixtureSet's fitted state is nn.Module buffers (registered in __init__),
    which a type checker reads through nn.Module.__getattr__ as `Tensor | Module`: a user's
    documented `model.n_components_.tolist()` was an error ("Module" has no attribute
    "tolist"), and so was any arithmetic on `means_` or `weights_`. Each buffer is
    declared a Tensor on the class."""
    from torchcbl.gmm import GaussianMixtureSet

    hints = typing.get_type_hints(GaussianMixtureSet)
    buffers = dict(GaussianMixtureSet(2, 3, max_components=2).named_buffers())
    assert {"n_components_", "means_", "weights_", "settings_"} <= set(buffers)
    wrong = {name: hints.get(name) for name in buffers if hints.get(name) is not torch.Tensor}
    assert not wrong, f"buffers not typed as Tensor: {wrong}"


def _policy_hint(func: Any) -> tuple[list[Any], Any]:
    """(parameter types, answer type) of a function's ``policy`` / ``teacher`` Callable."""
    hints = typing.get_type_hints(func)
    hint = hints.get("policy", hints.get("teacher"))
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        hint = typing.get_args(hint)[0]  # (policy: one Callable per arity, the same answer)
    params, answer = typing.get_args(hint)
    return params, answer


def test_a_policy_or_teacher_may_answer_a_numpy_integer_or_a_0d_tensor():
    """evaluate_policy documents the answer as an int, a numpy integer or a 0-d integer array
    or tensor (``logits.argmax()``), and the teaching loop takes a teacher's alike, but both
    hints said ``-> int``: a policy returning ``np.argmax(q)`` or ``logits.argmax()`` was an
    error to a type checker. The hints take what the code takes; the code takes those answers
    (checked here on a toy world)."""
    from _toy_envs import oracle, rare_regions_world

    from torchcbl import ConfidentTeacher, TeachingConfig, evaluate_policy

    for func in (evaluate_policy, ConfidentTeacher.__init__, ConfidentTeacher.resume):
        _, answer = _policy_hint(func)
        for cls in (int, np.int64, np.ndarray, torch.Tensor):
            assert _admits(answer, cls), (func.__qualname__, answer, cls)
    env = rare_regions_world()
    best = oracle(env)
    as_tensor = lambda obs, info: torch.tensor(best(obs, info))  # noqa: E731
    as_numpy = lambda obs: np.int64(best(obs, {}))  # noqa: E731
    ct = ConfidentTeacher(env, as_tensor, config=TeachingConfig(max_steps=3), progress=False)
    assert [r.teacher_action for r in ct.run().records] == [
        best(np.asarray(r.observation), {}) for r in ct.records
    ]
    assert len(evaluate_policy(as_numpy, env, n_steps=3)) == 3


def test_evaluate_policy_pairs_a_teacher_with_uses_info():
    """``evaluate_policy(teacher, env, ...)`` without ``uses_info=True`` calls a two-argument
    teacher with one and fails at its first step; the hint (one Callable of either arity for
    any ``uses_info``) let it through. Overloads pair them: uses_info omitted or False takes a
    policy(observation), True a teacher(observation, info); a bool known only at run time
    takes either."""
    from torchcbl import evaluate_policy

    arity: dict[Any, set[int]] = {}
    for overload in typing.get_overloads(evaluate_policy):
        hints = typing.get_type_hints(overload)
        flag, policy = hints["uses_info"], hints["policy"]
        key = typing.get_args(flag) if typing.get_origin(flag) is Literal else flag
        union = typing.get_origin(policy) in (typing.Union, types.UnionType)
        calls = typing.get_args(policy) if union else (policy,)
        arity[key] = {len(typing.get_args(c)[0]) for c in calls}
    assert arity == {(False,): {1}, (True,): {2}, bool: {1, 2}}, arity


def test_the_model_a_session_hands_out_is_typed_as_the_model_given():
    """The loop's learner is whatever ``model=`` gave (a GaussianMixtureSet by default), but
    ``on_refit`` was hinted to take a bare ``torch.nn.Module`` and ``snapshot()`` to return
    one: a callback ``on_refit(model: GaussianMixtureSet, n: int)`` (as
    scripts/investigate_corridor_requests.py has) was an error, and so was
    ``ct.snapshot().classify(x)`` (nn.Module's attributes read as ``Tensor | Module``). Both
    are typed as the ``model`` attribute is: any learner."""
    from torchcbl import ConfidentTeacher, GaussianMixtureSet

    for func in (ConfidentTeacher.__init__, ConfidentTeacher.resume):
        callback, none = typing.get_args(typing.get_type_hints(func)["on_refit"])
        (model, _), _ = typing.get_args(callback)
        assert none is type(None)
        assert model is Any or issubclass(model, GaussianMixtureSet), (func, model)
    snapshot = typing.get_type_hints(ConfidentTeacher.snapshot)["return"]
    assert snapshot is Any or issubclass(snapshot, GaussianMixtureSet), snapshot


def _fits(func: Any, **given: type) -> bool:
    """Whether some overload of ``func`` takes these keyword arguments of these classes."""
    for overload in typing.get_overloads(func) or [func]:
        hints = typing.get_type_hints(overload)
        if all(name in hints and _admits(hints[name], cls) for name, cls in given.items()):
            return True
    return False


def test_distance_rule_takes_max_std_or_quantile_not_both():
    """``DistanceRule(2.0, quantile=0.95)`` is a ValueError ("give max_std or quantile, not
    both"), but one signature with both optional let a type checker pass it. An overload
    each: max_std (or neither), or quantile alone."""
    from torchcbl import DistanceRule

    assert _fits(DistanceRule.__init__, max_std=float, quantile=type(None))
    assert _fits(DistanceRule.__init__, max_std=type(None), quantile=float)
    assert not _fits(DistanceRule.__init__, max_std=float, quantile=float)


def test_aic_and_bic_take_observations_and_actions_together():
    """``model.aic(X)`` without the actions is a ValueError ("pass both observations and
    actions, or neither"), but both were optional in one signature. An overload each: no
    arguments, or both."""
    from torchcbl import GaussianMixtureSet

    for method in (GaussianMixtureSet.aic, GaussianMixtureSet.bic):
        shapes = set()
        for overload in typing.get_overloads(method):
            params = list(inspect.signature(overload).parameters.values())[1:]
            shapes.add(tuple((p.name, p.default is p.empty) for p in params))
        assert shapes == {(), (("observations", True), ("actions", True))}, shapes


def test_corridor_env_hints_take_a_map_path_and_a_dict_of_world_fields():
    """CorridorEnv takes a map as a CorridorMap, a shipped name or a JSON path (a Path, too),
    and the robot as a WorldConfig or a dict of its fields (as gymnasium.make kwargs keep it,
    teaching_setup's), but its hints said ``CorridorMap | str`` and ``WorldConfig | None``,
    and load_map's ``str | Path`` (CorridorWorld hands it any os.PathLike): correct calls were
    errors to a type checker. The hints take what the code takes, checked here by running it."""
    import os

    from corridor.env import CorridorEnv
    from corridor.maps import load_map
    from corridor.world import WorldConfig

    shipped = ROOT / "corridor" / "maps" / "lshape.json"

    class MapPath(os.PathLike):  # an os.PathLike that is not a pathlib.Path
        def __fspath__(self) -> str:
            return str(shipped)

    assert _admits(typing.get_type_hints(load_map)["name_or_path"], MapPath)
    assert load_map(MapPath()).name == "lshape"
    hints = typing.get_type_hints(CorridorEnv.__init__)
    assert _admits(hints["corridor_map"], Path) and _admits(hints["corridor_map"], MapPath)
    assert _admits(hints["world_config"], dict)
    env = CorridorEnv(corridor_map=shipped, world_config={"forward_noise": 0.1})
    assert env.corridor_map.name == "lshape"
    assert env.world.config == WorldConfig(forward_noise=0.1)
