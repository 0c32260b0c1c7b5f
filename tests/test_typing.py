"""The public API's type hints, as a user's type checker (mypy, pyright) reads them.

The package ships py.typed (tests/test_package.py), so these hints are what a researcher's
editor checks their code against: a hint narrower than what the code takes rejects correct
code, one wider lets a mistake through. mypy is not a dependency, so the hints are read here
with typing's own introspection (get_type_hints, get_overloads) and the source's syntax.
"""

from __future__ import annotations

import ast
import typing
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]


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
