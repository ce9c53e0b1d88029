"""What the registered segmentation methods declare, for the modules below them.

:mod:`.params`, :mod:`.limits`, :mod:`.pipeline` and :mod:`.analysis` cannot import the
methods (the methods import them), yet they need what the methods declare: the menu
choices of ``SegmentParams.method`` (:data:`METHOD_CHOICES`), the methods that find the
number of segments (:data:`FINDS_K_METHODS`), those that compute the thesis block
maps (:data:`BLOCK_MAP_METHODS`) and each method's own parameter dataclass
(:data:`METHOD_PARAMS`). :func:`napari_polarseg.engine.methods.register_method`
fills them. The built-in methods register on the first read of any of them (or the
first lookup in the registry), not on ``import napari_polarseg.engine``: the registry
hands its loader to :func:`set_loader` when it is imported, and :func:`load_methods`
runs it once.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator, MutableMapping, MutableSet
from typing import Any

_lock = threading.RLock()
#: The registry's loader of the built-in methods, and whether it ran (or is running)
_state: dict[str, object] = {"loader": None, "loaded": False, "loading": False}


def set_loader(loader: Callable[[], None]) -> None:
    """Use ``loader`` (the registry's registration of the built-in methods) on the
    first read."""
    _state["loader"] = loader


def load_methods() -> None:
    """Register the built-in methods unless done: once, the first time anything reads
    the registered methods. A read while they register (the registration itself, in
    the same thread) returns at once; another thread waits for the end."""
    if _state["loaded"]:
        return
    with _lock:
        loader = _state["loader"]
        if _state["loaded"] or _state["loading"] or loader is None:
            return
        _state["loading"] = True
        try:
            loader()  # type: ignore[operator]
            _state["loaded"] = True
        finally:
            _state["loading"] = False


class MethodChoices(MutableMapping[str, Any]):
    """Method name → what it declares (menu text, parameter class), in registration
    order; reading it registers the built-in methods first (:func:`load_methods`),
    writing does not."""

    def __init__(self) -> None:
        self._items: dict[str, Any] = {}

    def __getitem__(self, name: str) -> Any:
        load_methods()
        return self._items[name]

    def __setitem__(self, name: str, text: Any) -> None:
        self._items[name] = text

    def __delitem__(self, name: str) -> None:
        del self._items[name]

    def __iter__(self) -> Iterator[str]:
        load_methods()
        return iter(list(self._items))

    def __len__(self) -> int:
        load_methods()
        return len(self._items)

    def __contains__(self, name: object) -> bool:
        load_methods()
        return name in self._items

    def __repr__(self) -> str:
        return f"MethodChoices({dict(self.items())!r})"


class MethodNames(MutableSet[str]):
    """A set of method names; reading it registers the built-in methods first
    (:func:`load_methods`), writing does not."""

    def __init__(self) -> None:
        self._names: set[str] = set()

    def add(self, name: str) -> None:
        self._names.add(name)

    def discard(self, name: str) -> None:
        self._names.discard(name)

    def __iter__(self) -> Iterator[str]:
        load_methods()
        return iter(sorted(self._names))

    def __len__(self) -> int:
        load_methods()
        return len(self._names)

    def __contains__(self, name: object) -> bool:
        load_methods()
        return name in self._names

    def __repr__(self) -> str:
        return f"MethodNames({sorted(self)!r})"


#: The registered methods that need no input besides the image, name → menu text, in
#: registration order: the choices of ``SegmentParams.method`` (``--method``, the
#: plugin's menu, ``params.json``).
METHOD_CHOICES = MethodChoices()
#: The registered methods that find the number of segments themselves when
#: ``n_segments`` is 0 (their ``finds_k`` is True).
FINDS_K_METHODS = MethodNames()
#: The registered methods that compute the block grid, the harmonic coefficients, the
#: PCA features and the reconstruction-error map (their ``block_maps`` is True): the
#: thesis method.
BLOCK_MAP_METHODS = MethodNames()
#: The parameter dataclass each registered method declares (its ``params_class``),
#: name → class, in registration order; a method without one is not listed.
METHOD_PARAMS = MethodChoices()


def computes_block_maps(method: str) -> bool:
    """Whether the method registered as ``method`` declares ``block_maps`` (it cuts
    the w × w block grid and computes the thesis maps in any case); False for a method
    that does not say so or is not registered."""
    return method in BLOCK_MAP_METHODS
