"""Command-line flags from a frozen dataclass of script arguments (the CleanRL pattern, without a dependency).

Each field ``name: T = default`` becomes ``--name`` (underscores -> dashes) of type ``T`` (int, float, str, Path),
a list of values for ``tuple[T, ...]`` fields (``--name A B C``), or a switch for ``bool`` fields (default False).
A string literal right below a field is its help text.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import textwrap
import typing
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")
_TYPES = {"int": int, "float": float, "str": str, "Path": Path, "bool": bool}


def field_docs(cls: type) -> dict[str, str]:
    """The string literals that follow the fields of a class body (attribute docstrings), by field name."""
    try:
        body = ast.parse(textwrap.dedent(inspect.getsource(cls))).body[0].body
    except (OSError, TypeError, IndexError, AttributeError):
        return {}
    docs = {}
    for statement, following in zip(body, body[1:], strict=False):
        if (
            isinstance(statement, ast.AnnAssign)
            and isinstance(statement.target, ast.Name)
            and isinstance(following, ast.Expr)
            and isinstance(following.value, ast.Constant)
            and isinstance(following.value.value, str)
        ):
            docs[statement.target.id] = following.value.value.strip()
    return docs


def parse_dataclass_args(cls: type[T], description: str | None = None, argv: list[str] | None = None) -> T:
    """Parse ``argv`` (default: sys.argv) into an instance of the dataclass ``cls``."""
    parser = argparse.ArgumentParser(
        description=description, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    hints = typing.get_type_hints(cls)
    docs = field_docs(cls)
    for field in dataclasses.fields(cls):
        flag = "--" + field.name.replace("_", "-")
        kind: Any = hints[field.name]
        if typing.get_origin(kind) is tuple:
            item = typing.get_args(kind)[0]
            if item not in _TYPES.values() or item is bool:
                raise TypeError(f"{cls.__name__}.{field.name}: unsupported tuple item type {item!r}")
            help_text = f"{docs.get(field.name, '')} (default {' '.join(map(str, field.default))})".strip()
            parser.add_argument(flag, type=item, nargs="+", default=field.default, help=help_text)
            continue
        if kind not in _TYPES.values():
            raise TypeError(f"{cls.__name__}.{field.name}: unsupported argument type {kind!r}")
        if kind is bool:
            parser.add_argument(flag, action="store_true", default=field.default, help=docs.get(field.name))
        else:
            help_text = f"{docs.get(field.name, '')} (default {field.default})".strip()
            parser.add_argument(flag, type=kind, default=field.default, help=help_text)
    values = vars(parser.parse_args(argv))
    return cls(**{name: tuple(v) if isinstance(v, list) else v for name, v in values.items()})
