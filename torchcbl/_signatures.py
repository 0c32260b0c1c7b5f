"""Reading a callable's signature before it is called: whether a teacher or a policy can take
the call the loop will make (a light module: no torch, so the strategies may use it)."""

from __future__ import annotations

import inspect
import sys
import types
from typing import Any, NamedTuple

# a torch network's action, in the advice for wrapping one as a teacher (``net`` in the call)
_NET_ACTION = "int(net(torch.as_tensor(obs, dtype=torch.float32)).argmax())"
_MAX_WRAPPERS = 100  # __wrapped__ hops read at most (inspect.unwrap stops at the recursion limit)


def _module_forward(fn: Any) -> Any:
    """The ``forward`` of ``fn`` where it is a ``torch.nn.Module`` (whose ``__call__``, a
    generic ``(*args, **kwargs)``, runs it), else None. Torch is not imported for it: an object
    can be a module only once torch has been imported."""
    torch = sys.modules.get("torch")
    module = getattr(getattr(torch, "nn", None), "Module", None)
    if isinstance(module, type) and isinstance(fn, module):
        return getattr(fn, "forward", None)
    return None


def called_parameters(fn: Any) -> tuple[list[inspect.Parameter] | None, str | None]:
    """The parameters ``fn`` is called with (None where its signature is unknown), and how
    they were read: None from ``fn``'s own signature, ``"forward"`` from a torch module's
    ``forward``, ``"__wrapped__"`` through ``__wrapped__``. The called function's own
    signature first, not that of what a ``functools.wraps`` adapter wraps (``@wraps(policy) def
    teacher(obs, info)`` would read as the policy's ``(obs)``); where it is a generic
    ``(*args, **kwargs)`` wrapper (``torch.no_grad()``, a decorator, ``lru_cache``), the wrapped
    function's, which is what the call reaches, one ``__wrapped__`` at a time, at most
    ``_MAX_WRAPPERS`` of them; for a ``torch.nn.Module`` (whose ``__call__`` is such a
    wrapper), its ``forward``'s."""
    params, through, _ = _called(fn)
    return params, through


def _called(fn: Any) -> tuple[list[inspect.Parameter] | None, str | None, Any]:
    """:func:`called_parameters`, and the torch module whose ``forward`` was read where it was
    (the object at the end of a ``__wrapped__`` chain, e.g. ``torch.no_grad()(net)``'s net),
    else None."""
    star = (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)
    sig: inspect.Signature | None = None
    through: str | None = None
    hops: list[str] = []  # how each hop so far went on: "__wrapped__" or "forward"
    seen: dict[int, Any] = {}  # the objects are kept: a freed one's id may be reused
    module: Any = None  # the module whose forward the walk went on to
    owner: Any = None  # that module, where the signature read is its forward's
    for _ in range(_MAX_WRAPPERS):
        if fn is None or id(fn) in seen:  # the end of the chain, or a loop
            break
        seen[id(fn)] = fn
        try:
            here = inspect.signature(fn, follow_wrapped=False)
        except (TypeError, ValueError):
            here = None
        if here is not None:
            sig = here
            through = "forward" if "forward" in hops else (hops[0] if hops else None)
            owner = module if through == "forward" else None
            if not (here.parameters and all(p.kind in star for p in here.parameters.values())):
                break
        wrapped = getattr(fn, "__wrapped__", None)
        if wrapped is None:  # an nn.Module's __call__ runs its forward
            wrapped = _module_forward(fn)
            hops.append("forward")
            if wrapped is not None and module is None:
                module = fn
        else:
            hops.append("__wrapped__")
        if wrapped is not None and inspect.ismethod(fn) and not inspect.ismethod(wrapped):
            # a bound method's __wrapped__ is the plain function: bind it as the call does
            # (@torch.no_grad() def act(self, obs, info) is called as agent.act(obs, info))
            try:
                wrapped = types.MethodType(wrapped, fn.__self__)
            except TypeError:  # not a function to bind
                pass
        fn = wrapped
    return (None if sig is None else list(sig.parameters.values())), through, owner


class Mismatch(NamedTuple):
    """Why a callable cannot take a call of positional arguments (see :func:`cannot_take`)."""

    takes: str  #: what it takes, e.g. "three takes (obs, info, k)"
    missing: int  #: positional arguments the call passes that it has no parameter for
    keyword_only: tuple[str, ...]  #: its required keyword-only parameters that would take them
    extra: tuple[str, ...]  #: its required parameters the call never gives (beyond its own)
    positional: tuple[str, ...]  #: the names of its positional parameters

    def advice(self, call: str) -> str:
        """What to change in it for the ``call`` (e.g. "(observation, info)") bar a missing
        parameter (the caller's own advice): a keyword-only parameter the call means to pass
        by position, or a required one the call never passes."""
        parts = []
        if self.keyword_only:
            them = "it" if len(self.keyword_only) == 1 else "them"
            are = "is" if len(self.keyword_only) == 1 else "are"
            want = ", ".join(self.positional + self.keyword_only)
            parts.append(
                f"{', '.join(self.keyword_only)} {are} keyword-only, but the call {call} passes "
                f"its arguments positionally: make {them} positional, ({want})"
            )
        if self.extra:
            one = len(self.extra) == 1
            parts.append(
                f"it is called with exactly {call}: give {', '.join(self.extra)} "
                f"{'a default' if one else 'defaults'} or bind {'it' if one else 'them'} with "
                "functools.partial"
            )
        return "; ".join(parts)


def cannot_take(fn: Any, n_args: int) -> Mismatch | None:
    """Why ``fn`` cannot be called with ``n_args`` positional arguments, as its signature says
    (its ``takes``, e.g. "teacher takes (obs, info)"; for a torch module "Net.forward takes
    (x)"), or None where it can or its signature is unknown (a builtin). Read before any
    call, so that a TypeError of ``fn``'s own is never reworded."""
    params, through, module = _called(fn)
    if params is None:
        return None
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    varargs = any(p.kind is p.VAR_POSITIONAL for p in params)
    keyword = [p.name for p in params if p.kind is p.KEYWORD_ONLY and p.default is p.empty]
    slots = 0 if varargs else max(0, n_args - len(positional))  # arguments with no parameter
    moved = keyword[:slots]  # keyword-only parameters the call's extra arguments are meant for
    extra = [p.name for p in positional[n_args:] if p.default is p.empty] + keyword[slots:]
    if not slots and not extra:
        return None
    shown = [p.name if p.default is p.empty else f"{p.name}=..." for p in positional]
    shown += [f"*{p.name}" for p in params if p.kind is p.VAR_POSITIONAL]
    kw_only = [p for p in params if p.kind is p.KEYWORD_ONLY]
    if kw_only and not varargs:
        shown.append("*")
    shown += [p.name if p.default is p.empty else f"{p.name}=..." for p in kw_only]
    shown += [f"**{p.name}" for p in params if p.kind is p.VAR_KEYWORD]
    name = getattr(fn, "__qualname__", None) or type(fn).__name__
    if through == "forward":  # a torch module, read as the forward its __call__ runs
        # named by the module's class, also under a wrapper (torch.no_grad()(net)), whose
        # own type (a function) says nothing
        takes = f"{type(module).__qualname__}.forward takes ({', '.join(shown)})"
    elif through:  # a generic (*args, **kwargs) wrapper, read as what its __wrapped__ names
        takes = (
            f"{name}, a wrapper of *args/**kwargs, wraps (its __wrapped__) a function that "
            f"takes ({', '.join(shown)}); if the wrapper itself takes more, give it that "
            "signature"
        )
    else:
        takes = f"{name} takes ({', '.join(shown)})"
    names = tuple(p.name for p in positional)
    return Mismatch(takes, slots - len(moved), tuple(moved), tuple(extra), names)


def refuse_unless_a_teacher(
    teacher: Any, who: str, wrap: str = "lambda obs, info: policy(obs)"
) -> None:
    """Raise TypeError, before any call, where ``teacher``'s signature cannot take the loop's
    ``teacher(observation, info)``: a policy of the observation alone, given for a teacher, or
    a teacher with a required parameter the loop never gives or one it gives by keyword.
    ``who`` begins the message (what was given the teacher); ``wrap`` is the advice's wrapping
    of a policy, in the call the user makes."""
    why = cannot_take(teacher, 2)
    if why is None:
        return
    head = f"{who}: a teacher is called as teacher(observation, info), but {why.takes}"
    also = why.advice("(observation, info)")
    also = f" ({also})" if also and why.missing else also
    if why.missing and _module_forward(teacher) is not None:
        # a network: its forward takes a tensor and answers scores, not the loop's int
        net = wrap.replace("policy(obs)", _NET_ACTION)
        raise TypeError(
            f"{head}; a network of the observation alone is a policy, not a teacher: wrap it, "
            f"e.g. {net}{also}"
        )
    if why.missing:
        raise TypeError(
            f"{head}; give it an info parameter (it may ignore it), or wrap a policy of the "
            f"observation alone: {wrap}{also}"
        )
    raise TypeError(f"{head}; {also}")
