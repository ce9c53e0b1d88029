"""Each method's own parameters inside :class:`~napari_polarseg.engine.params.SegmentParams`.

A method declares its parameters as a frozen dataclass whose fields carry a
:class:`~napari_polarseg.engine.param_spec.ParamSpec` (its ``params_class``; e.g.
:class:`~napari_polarseg.engine.methods.thesis.ThesisParams`). :class:`MethodParams` holds
the values of those parameters by method name; :func:`route` puts a parameter given by
name alone (``SegmentParams(window=10)``, a ``params.json`` written before the methods had
their own parameters) into the parameters of the method that declares it.

Which method a name belongs to (:func:`owner_of`): the chosen method when its class
declares the name, else the first registered method whose class does (the thesis method
for the block parameters, which the thesis maps of any run read).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import fields, is_dataclass, replace
from functools import cache
from typing import Any

from .errors import PolarsegError
from .registered import METHOD_PARAMS

#: Returned by :func:`method_value` for a name no registered method declares.
MISSING_VALUE = object()


@cache
def field_names(cls: type) -> tuple[str, ...]:
    """The field names of the parameter dataclass ``cls``."""
    return tuple(f.name for f in fields(cls))


@cache
def default_of(cls: type) -> Any:
    """The default instance of the parameter dataclass ``cls`` (made once)."""
    return cls()


def params_class(method: str) -> type | None:
    """The parameter dataclass the method registered as ``method`` declares (None: it
    has no parameters of its own, or no such method is registered)."""
    return METHOD_PARAMS.get(method)


def owner_of(name: str, method: str) -> str | None:
    """The method whose parameters hold ``name``: ``method`` when its class declares
    it, else the first registered method whose class does; None when none does."""
    cls = params_class(method)
    if cls is not None and name in field_names(cls):
        return method
    for owner, cls in METHOD_PARAMS.items():
        if name in field_names(cls):
            return owner
    return None


def from_values(method: str, values: Any) -> Any:
    """The parameters of ``method`` from a mapping (a ``params.json`` entry) or an
    instance of its class (returned as it is); PolarsegError naming what is wrong."""
    cls = params_class(method)
    if cls is None:
        raise PolarsegError(f"method {method!r} has no parameters of its own (or is unknown)")
    if isinstance(values, cls):
        return values
    if not isinstance(values, Mapping):
        raise PolarsegError(f"the parameters of method {method!r} must be an object")
    unknown = set(values) - set(field_names(cls))
    if unknown:
        raise PolarsegError(
            f"unknown parameter(s) of method {method!r}: {', '.join(sorted(unknown))}"
        )
    try:
        return cls(**values)
    except TypeError as exc:
        raise PolarsegError(f"method {method!r}: a parameter has the wrong type ({exc})") from None


class MethodParams(Mapping[str, Any]):
    """Method name → that method's parameters (an instance of its ``params_class``).

    Immutable and hashable (a field of the frozen ``SegmentParams``). An entry equal to
    its class's defaults is dropped, so parameters that run alike compare equal; a
    method without an entry runs with its defaults (:meth:`of`).
    """

    def __init__(self, items: Mapping[str, Any] | Iterable[tuple[str, Any]] = ()) -> None:
        kept = {}
        for name, value in dict(items).items():
            value = value if is_dataclass(value) else from_values(name, value)
            if value != default_of(type(value)):
                kept[name] = value
        self._items = dict(sorted(kept.items()))

    def __getitem__(self, name: str) -> Any:
        return self._items[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __hash__(self) -> int:
        return hash(tuple(self._items.items()))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Mapping) and dict(self.items()) == dict(other.items())

    def __repr__(self) -> str:
        return f"MethodParams({self._items!r})"

    def of(self, method: str) -> Any:
        """The parameters of ``method``: its entry, else its class's defaults (None for a
        method without parameters of its own)."""
        if method in self._items:
            return self._items[method]
        cls = params_class(method)
        return None if cls is None else default_of(cls)


def route(method: str, stored: MethodParams, values: Mapping[str, Any]) -> MethodParams:
    """``stored`` with each of ``values`` (parameter name → value) set in the parameters
    of the method that declares it (:func:`owner_of`, ``method`` first); PolarsegError
    naming the names no registered method declares."""
    by_owner: dict[str, dict[str, Any]] = {}
    unknown = []
    for name, value in values.items():
        owner = owner_of(name, method)
        if owner is None:
            unknown.append(name)
        else:
            by_owner.setdefault(owner, {})[name] = value
    if unknown:
        raise PolarsegError(f"unknown parameter(s): {', '.join(sorted(unknown))}")
    items = dict(stored.items())
    for owner, changes in by_owner.items():
        items[owner] = replace(stored.of(owner), **changes)
    return MethodParams(items)


def method_value(method: str, stored: MethodParams, name: str) -> Any:
    """The value of the method parameter ``name`` as ``SegmentParams`` reads it (the
    method :func:`owner_of` names), or :data:`MISSING_VALUE`."""
    owner = owner_of(name, method)
    if owner is None:
        return MISSING_VALUE
    return getattr(stored.of(owner), name)
