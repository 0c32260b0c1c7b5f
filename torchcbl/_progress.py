"""The progress bar the teaching loop and the experiments draw (tqdm)."""

from __future__ import annotations

from typing import Any


def progress_bar(*, total: int | None, desc: str, unit: str, show: bool) -> Any:
    """A tqdm progress bar: a notebook widget where Jupyter can draw one (ipywidgets is
    installed), else the text bar; with ``show`` False a disabled plain bar, so that nothing
    (not even tqdm's warning about a missing ipywidgets) is printed."""
    if show:
        try:
            import ipywidgets  # noqa: F401  (tqdm.auto's notebook bar needs it)
            from tqdm.auto import tqdm
        except ImportError:
            from tqdm import tqdm
    else:
        from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit=unit, disable=not show)
