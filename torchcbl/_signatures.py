"""Reading a callable's signature before it is called: whether a teacher or a policy can take
the call the loop will make (a light module: no torch, so the strategies may use it)."""

from __future__ import annotations

import inspect
import types
from typing import Any

_MAX_WRAPPERS = 100  # __wrapped__ hops read at most (inspect.unwrap stops at the recursion limit)


def called_parameters(fn: Any) -> tuple[list[inspect.Parameter] | None, bool]:
    """The parameters ``fn`` is called with (None where its signature is unknown), and whether
    they were read through ``__wrapped__``. The called function's own signature first, not
    that of what a ``functools.wraps`` adapter wraps (``@wraps(policy) def teacher(obs, info)``
    would read as the policy's ``(obs)``); where it is a generic ``(*args, **kwargs)`` wrapper
    (``torch.no_grad()``, a decorator, ``lru_cache``), the wrapped function's, which is what
    the call reaches, one ``__wrapped__`` at a time, at most ``_MAX_WRAPPERS`` of them."""
    star = (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)
    sig: inspect.Signature | None = None
    through = False
    seen: dict[int, Any] = {}  # the objects are kept: a freed one's id may be reused
    for hop in range(_MAX_WRAPPERS):
        if fn is None or id(fn) in seen:  # the end of the chain, or a loop
            break
        seen[id(fn)] = fn
        try:
            here = inspect.signature(fn, follow_wrapped=False)
        except (TypeError, ValueError):
            here = None
        if here is not None:
            sig, through = here, hop > 0
            if not (here.parameters and all(p.kind in star for p in here.parameters.values())):
                break
        wrapped = getattr(fn, "__wrapped__", None)
        if wrapped is not None and inspect.ismethod(fn) and not inspect.ismethod(wrapped):
            # a bound method's __wrapped__ is the plain function: bind it as the call does
            # (@torch.no_grad() def act(self, obs, info) is called as agent.act(obs, info))
            try:
                wrapped = types.MethodType(wrapped, fn.__self__)
            except TypeError:  # not a function to bind
                pass
        fn = wrapped
    return (None if sig is None else list(sig.parameters.values())), through


def cannot_take(fn: Any, n_args: int) -> str | None:
    """Why ``fn`` cannot be called with ``n_args`` positional arguments, as its signature says
    (e.g. "teacher takes (obs, info)"), or None where it can or its signature is unknown (a
    builtin). Read before any call, so that a TypeError of ``fn``'s own is never reworded."""
    params, through = called_parameters(fn)
    if params is None:
        return None
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    required = sum(p.default is p.empty for p in positional)
    varargs = any(p.kind is p.VAR_POSITIONAL for p in params)
    if required <= n_args and (varargs or len(positional) >= n_args):
        return None
    shown = [p.name if p.default is p.empty else f"{p.name}=..." for p in positional]
    shown += [f"*{p.name}" for p in params if p.kind is p.VAR_POSITIONAL]
    name = getattr(fn, "__qualname__", None) or type(fn).__name__
    if through:  # a generic (*args, **kwargs) wrapper, read as what its __wrapped__ names
        return (
            f"{name}, a wrapper of *args/**kwargs, wraps (its __wrapped__) a function that "
            f"takes ({', '.join(shown)}); if the wrapper itself takes more, give it that "
            "signature"
        )
    return f"{name} takes ({', '.join(shown)})"


def refuse_unless_a_teacher(
    teacher: Any, who: str, wrap: str = "lambda obs, info: policy(obs)"
) -> None:
    """Raise TypeError, before any call, where ``teacher``'s signature cannot take the loop's
    ``teacher(observation, info)``: a policy of the observation alone, given for a teacher.
    ``who`` begins the message (what was given the teacher); ``wrap`` is the advice's wrapping
    of a policy, in the call the user makes."""
    takes = cannot_take(teacher, 2)
    if takes is not None:
        raise TypeError(
            f"{who}: a teacher is called as teacher(observation, info), but {takes}; give it an "
            f"info parameter (it may ignore it), or wrap a policy of the observation alone: "
            f"{wrap}"
        )
