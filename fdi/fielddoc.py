"""Units and docs of a parameter dataclass's fields, kept in one table beside the class.

``docs/reference/config.md`` is generated from each field's ``metadata["unit"]`` and
``metadata["doc"]`` (:mod:`firmware_host.commands.reference`). A class whose fields' own lines
already hold their bounds may keep its docs in a table instead::

    @documented({"alpha": {"unit": "-", "doc": "significance level"}})
    @dataclass(frozen=True)
    class Params:
        alpha: float = field(default=0.05, metadata={"ge": 1e-15, "le": 0.5})

The decorator merges each entry into the field's metadata (the bounds stay as they are), and
fails at import on an entry for a field the class does not have.
"""

from __future__ import annotations

import types
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

T = TypeVar("T")


def documented(docs: Mapping[str, Mapping[str, str]]) -> Callable[[type[T]], type[T]]:
    """A class decorator (outside ``@dataclass``) adding ``docs[field]`` to each field's
    metadata."""

    def attach(cls: type[T]) -> type[T]:
        fields: dict[str, Any] = getattr(cls, "__dataclass_fields__", {})
        unknown = sorted(set(docs) - set(fields))
        if unknown:
            raise TypeError(f"{cls.__name__} has no field {', '.join(unknown)}")
        for name, doc in docs.items():
            f = fields[name]
            f.metadata = types.MappingProxyType({**f.metadata, **doc})
        return cls

    return attach
