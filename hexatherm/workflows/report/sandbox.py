"""The bounds of a render: a lab's template ends, in bounded memory, or is refused.

A lab's templates come from a folder (often a shared drive) that is data, not a program:
Jinja2's sandbox keeps them from Python's internals, and :class:`BoundedEnvironment`
keeps them from running forever or filling the memory. Every bound trips on a count,
never on the clock, so that a refusal is the same on any machine and under any load:

* **operations**: every loop iteration and every call (a macro, a filter's callable, a
  method) counts one; more than :data:`MAX_OPERATIONS` in one render is refused (a
  report of the shipped sessions takes a few thousand);
* **values**: a string, list or number a template makes (``*``, ``+``, ``~``, ``**``,
  ``%``, ``str.format``, a method's width, the filters that pad, repeat, split or
  replace) is checked *before* it is made: at most :data:`MAX_VALUE_CHARS` items, an
  integer of at most :data:`MAX_INT_BITS` bits;
* **the page**: every value printed, every loop's text and every ``asset()`` embedded
  count towards :data:`MAX_PAGE_CHARS`.

Beyond those, two nets that do not depend on a template's tricks: on Linux the render's
address space may grow by at most :data:`MAX_RENDER_BYTES` (a :class:`MemoryError` is
a refusal, the process lives on), and a render running longer than
:data:`MAX_RENDER_S` is stopped at its next operation. Each is a
:class:`jinja2.TemplateRuntimeError` that :mod:`hexatherm.workflows.report.render`
turns into one line naming the template's file and line.
"""

from __future__ import annotations

import contextlib
import os
import re
import string
import time
from collections.abc import Callable, Iterable, Iterator
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jinja2
from jinja2 import nodes
from jinja2.compiler import CodeGenerator, Frame
from jinja2.sandbox import SandboxedEnvironment

#: loop iterations and calls in one render (calibration-campaign's report takes 4617)
MAX_OPERATIONS = 1_000_000
#: items of one string, list or tuple a template makes
MAX_VALUE_CHARS = 16 * 2**20
#: bits of one integer a template makes (1233 decimal digits)
MAX_INT_BITS = 4096
#: characters of a page (values printed, loops' text, embedded assets)
MAX_PAGE_CHARS = 256 * 2**20
#: how much the process's address space may grow while a page renders (Linux)
MAX_RENDER_BYTES = 4 * 2**30
#: how long a render may run, looked at every 4096 operations (a net: the counts trip first)
MAX_RENDER_S = 120.0


class _Bound(jinja2.TemplateRuntimeError):
    """A bound of the render exceeded (rendered as a refusal naming the template)."""


@dataclass
class Budget:
    """What one render has spent."""

    operations: int = 0
    chars: int = 0
    started: float = field(default_factory=time.monotonic)


_budget: ContextVar[Budget | None] = ContextVar("hexatherm_render_budget", default=None)


def tick(count: int = 1) -> None:
    """Count ``count`` operations of the render under way."""
    budget = _budget.get()
    if budget is None:
        return
    budget.operations += count
    if budget.operations > MAX_OPERATIONS:
        raise _Bound(
            f"more than {MAX_OPERATIONS} loop iterations and calls in one page "
            "(a loop that does not end?)"
        )
    if budget.operations & 4095 == 0 and time.monotonic() - budget.started > MAX_RENDER_S:
        raise _Bound(f"the page did not render in {MAX_RENDER_S:g} s")


def spend(chars: int) -> None:
    """Count ``chars`` characters of the page under way."""
    budget = _budget.get()
    if budget is None:
        return
    budget.chars += chars
    if budget.chars > MAX_PAGE_CHARS:
        raise _Bound(f"a page of more than {MAX_PAGE_CHARS} characters")


def _too_long(size: int, what: str) -> None:
    if size > MAX_VALUE_CHARS:
        raise _Bound(f"{what} of {size} items; a template makes at most {MAX_VALUE_CHARS}")


def _int_bits(value: int, what: str) -> None:
    if value > MAX_INT_BITS:
        raise _Bound(f"{what} of {value} bits; a template makes at most {MAX_INT_BITS}")


def _sized(value: Any) -> int | None:
    return len(value) if isinstance(value, str | bytes | list | tuple) else None


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def checked(value: Any) -> Any:
    """``value``, when it is no longer than a template may make."""
    size = _sized(value)
    if size is not None:
        _too_long(size, "a value")
    elif _is_int(value):
        _int_bits(value.bit_length(), "an integer")
    return value


_WIDTHS = re.compile(r"\d+")
_PERCENT = re.compile(r"%(?:\([^)]*\))?[-#0 +]*(\*|\d+)?(?:\.(\*|\d+))?[hlL]?[a-zA-Z%]")


def _ints(values: Iterable[Any]) -> int:
    return sum(abs(v) for v in values if _is_int(v))


def _format_size(text: str, args: tuple[Any, ...], kwargs: dict[str, Any]) -> int:
    """An upper bound of the widths and precisions ``str.format`` would pad to."""
    total = 0
    try:
        parsed = list(string.Formatter().parse(text))
    except ValueError:
        return 0  # the call raises it
    for _, _, spec, _ in parsed:
        if spec:
            total += sum(int(n) for n in _WIDTHS.findall(spec))
            if "{" in spec:  # a nested width: any number given
                total += _ints([*args, *kwargs.values()])
    return total


def _percent_size(text: str, args: Any) -> int:
    """An upper bound of the widths and precisions ``text % args`` would pad to."""
    total = 0
    given = args if isinstance(args, tuple) else (args,)
    for match in _PERCENT.finditer(text):
        for part in match.groups():
            if part == "*":
                total += _ints(given)
            elif part:
                total += int(part)
    return total


def _binop_size(operator: str, left: Any, right: Any) -> None:
    """Refuse ``left operator right`` when the result would be too large."""
    if operator == "**" and _is_int(left) and _is_int(right) and right > 0 and abs(left) > 1:
        _int_bits(left.bit_length() * right, "a power")
    elif operator == "*":
        for seq, times in ((left, right), (right, left)):
            size = _sized(seq)
            if size is not None and _is_int(times):
                _too_long(size * max(times, 0), "a repetition")
        if _is_int(left) and _is_int(right):
            _int_bits(left.bit_length() + right.bit_length(), "a product")
    elif operator == "+":
        a, b = _sized(left), _sized(right)
        if a is not None and b is not None:
            _too_long(a + b, "a sum")
    elif operator == "%" and isinstance(left, str):
        _too_long(len(left) + _percent_size(left, right), "a formatted string")


def _check_call(obj: Any, args: tuple[Any, ...], kwargs: dict[str, Any]) -> None:
    """Refuse a call of a string's method that would make too long a string (a width)."""
    target = getattr(obj, "__wrapped__", obj)  # the sandbox's str.format wrapper
    owner = getattr(target, "__self__", None)
    if not isinstance(owner, str):
        return
    name = getattr(target, "__name__", "")
    if name in ("format", "format_map"):
        mapping = args[0] if name == "format_map" and args and isinstance(args[0], dict) else {}
        size = _format_size(owner, args, {**kwargs, **mapping})
        _too_long(len(owner) + size, "a formatted string")
    elif name == "replace" and len(args) >= 2 and isinstance(args[0], str):
        new = args[1]
        count = owner.count(args[0]) if args[0] else len(owner) + 1
        _too_long(len(owner) + count * len(str(new)), "a replacement")
    else:
        _too_long(len(owner) + _ints([*args, *kwargs.values()]), "a padded string")


def _filter(
    original: Callable[..., Any], size: Callable[..., int], what: str
) -> Callable[..., Any]:
    """The filter ``original``, refused when ``size(*args)`` is too large."""

    def bounded(*args: Any, **kwargs: Any) -> Any:
        _too_long(size(*args, **kwargs), what)
        return checked(original(*args, **kwargs))

    for attribute in ("jinja_pass_arg",):  # pass_context, pass_eval_context ...
        if hasattr(original, attribute):
            setattr(bounded, attribute, getattr(original, attribute))
    return bounded


def _value_of(args: tuple[Any, ...]) -> Any:
    """The filtered value (after an eval context or environment the filter is passed)."""
    return next((a for a in args if not isinstance(a, jinja2.Environment | nodes.EvalContext)), "")


def _len(value: Any) -> int:
    try:
        return len(value)
    except TypeError:
        return len(str(value))


def _padding(*args: Any, **kwargs: Any) -> int:
    return _len(_value_of(args)) + _ints([*args, *kwargs.values()])


def _indented(*args: Any, **kwargs: Any) -> int:
    values = [a for a in args if not isinstance(a, jinja2.Environment | nodes.EvalContext)]
    text = str(values[0]) if values else ""
    width = values[1] if len(values) > 1 else kwargs.get("width", 4)
    per_line = abs(width) if _is_int(width) else _len(width)
    return len(text) + (text.count("\n") + 1) * per_line


def _joined(*args: Any, **kwargs: Any) -> int:
    values = [a for a in args if not isinstance(a, jinja2.Environment | nodes.EvalContext)]
    items = values[0] if values else ()
    separator = values[1] if len(values) > 1 else kwargs.get("d", "")
    try:
        count = len(items)
    except TypeError:
        return 0
    return _summed(items) + count * _len(separator)


def _replaced(*args: Any, **kwargs: Any) -> int:
    values = [a for a in args if not isinstance(a, jinja2.Environment | nodes.EvalContext)]
    text = str(values[0]) if values else ""
    old = str(values[1] if len(values) > 1 else kwargs.get("old", ""))
    new = str(values[2] if len(values) > 2 else kwargs.get("new", ""))
    return len(text) + (text.count(old) if old else len(text) + 1) * len(new)


def _percent_filter(*args: Any, **kwargs: Any) -> int:
    text = str(_value_of(args))
    return len(text) + _percent_size(text, tuple(args[1:]) + tuple(kwargs.values()))


def _summed(*args: Any, **kwargs: Any) -> int:
    items = _value_of(args) if args else ()
    try:
        return sum(_len(item) for item in items if _sized(item) is not None)
    except TypeError:
        return 0


#: the filters that make more than they are given, and the size they would make
_AMPLIFYING = {
    "center": (_padding, "a centred string"),
    "indent": (_indented, "an indented string"),
    "join": (_joined, "a joined string"),
    "batch": (_padding, "a batch"),
    "slice": (_padding, "a slice"),
    "replace": (_replaced, "a replacement"),
    "format": (_percent_filter, "a formatted string"),
    "sum": (_summed, "a sum"),
}


def _bounded_range(*args: Any) -> range:
    """``range``, of at most 100 000 numbers (the sandbox's bound), refused in one line."""
    for value in args:
        if not _is_int(value):
            raise _Bound(f"range() of {value!r}: integers only")
    numbers = range(*args)
    if len(numbers) > 100_000:
        raise _Bound(f"range() of {len(numbers)} numbers; a template counts to 100000")
    return numbers


def bounded_iter(iterable: Any, text: int) -> Iterator[Any]:
    """The items of a loop's ``iterable``, each counted as an operation and the loop
    body's ``text`` characters of the page."""
    for item in iterable:
        tick()
        spend(text)
        yield item


class _Generator(CodeGenerator):
    """Jinja2's code, with each loop's iterable and each ``~`` counted."""

    def visit_For(self, node: nodes.For, frame: Frame) -> None:
        text = sum(len(data.data) for data in node.find_all(nodes.TemplateData))
        counted = nodes.Call(
            nodes.EnvironmentAttribute("hexatherm_iter"),
            [node.iter, nodes.Const(text)],
            [],
            None,
            None,
            lineno=node.lineno,
        )
        copy = nodes.For(
            node.target,
            counted,
            node.body,
            node.else_,
            node.test,
            node.recursive,
            lineno=node.lineno,
        )
        copy.environment = node.environment
        super().visit_For(copy, frame)

    def visit_Concat(self, node: nodes.Concat, frame: Frame) -> None:
        self.write("environment.hexatherm_checked(")
        super().visit_Concat(node, frame)
        self.write(")")


class BoundedEnvironment(SandboxedEnvironment):
    """The sandbox, with the bounds of this module."""

    code_generator_class = _Generator
    intercepted_binops = frozenset({"*", "**", "+", "%"})

    def __init__(self, **options: Any) -> None:
        super().__init__(**options)
        self.hexatherm_iter = bounded_iter
        self.hexatherm_read: set[Path] = set()  # every file read (the report's render.py)
        self.hexatherm_checked = checked
        self.globals["range"] = _bounded_range
        self.globals.pop("lipsum", None)  # n paragraphs of filler: nothing for a report
        for name, (size, what) in _AMPLIFYING.items():
            self.filters[name] = _filter(self.filters[name], size, what)

    def call_binop(self, context: jinja2.runtime.Context, operator: str, left: Any, right: Any):
        tick()
        _binop_size(operator, left, right)
        return checked(super().call_binop(context, operator, left, right))

    def call(__self, __context: Any, __obj: Any, *args: Any, **kwargs: Any) -> Any:  # noqa: N805
        tick()
        _check_call(__obj, args, kwargs)
        return checked(super().call(__context, __obj, *args, **kwargs))


def _address_space() -> int | None:
    """The process's address space now (bytes), on Linux; ``None`` elsewhere."""
    try:
        with open("/proc/self/statm", "rb") as handle:
            pages = int(handle.read().split()[0])
        return pages * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None


@contextlib.contextmanager
def _memory_bound(extra: int) -> Iterator[None]:
    """The address space may grow by ``extra`` bytes in the block (Linux: ``RLIMIT_AS``;
    an allocation beyond is a :class:`MemoryError`); restored after."""
    try:
        import resource
    except ImportError:  # not a POSIX system
        yield
        return
    now = _address_space()
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    limit = None if now is None else now + extra
    if limit is None or (soft != resource.RLIM_INFINITY and soft <= limit):
        yield
        return
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))


@contextlib.contextmanager
def render_bounds(memory: int | None = None) -> Iterator[Budget]:
    """The bounds of one render, for the block (nested renders share the outer one's)."""
    outer = _budget.get()
    if outer is not None:
        yield outer
        return
    budget = Budget()
    token = _budget.set(budget)
    try:
        with _memory_bound(MAX_RENDER_BYTES if memory is None else memory):
            yield budget
    finally:
        _budget.reset(token)


__all__ = [
    "MAX_OPERATIONS",
    "MAX_PAGE_CHARS",
    "MAX_VALUE_CHARS",
    "BoundedEnvironment",
    "Budget",
    "render_bounds",
    "spend",
    "tick",
]
