"""What the package exports: every error class python/README.md names is importable from
``tacmesh`` (the README is read for them, so a class it names and the package does not export
fails here), every error class of the package is exported, and ``__all__`` holds what is there.
"""

from __future__ import annotations

import builtins
import importlib
import re
from pathlib import Path

import tacmesh
from tacmesh import subscriber, wire

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_paragraph(heading: str) -> str:
    """The README's paragraph that starts with ``heading`` (up to the next blank line)."""
    text = README.read_text(encoding="utf-8")
    start = text.index(heading)
    end = text.find("\n\n", start)
    return text[start : end if end >= 0 else len(text)]


def named_classes(text: str) -> list[str]:
    """The names in backquotes in ``text`` that are spelt like a class (``WireError``)."""
    return sorted(set(re.findall(r"`([A-Z][A-Za-z0-9]*[a-z][A-Za-z0-9]*)`", text)))


def package_errors() -> set[str]:
    """The exception classes the package's modules define."""
    return {
        name
        for module in (wire, subscriber)
        for name, value in vars(module).items()
        if isinstance(value, type)
        and issubclass(value, BaseException)
        and value.__module__ == module.__name__
    }


def test_every_class_the_readme_names_for_errors_is_importable_from_tacmesh() -> None:
    named = named_classes(readme_paragraph("**Errors and reconnection.**"))
    assert {"WireError", "UntrustedServer", "InvalidNumber", "Refused"} <= set(named), named
    package = importlib.import_module("tacmesh")
    for name in named:
        if isinstance(getattr(builtins, name, None), type):
            continue  # a built-in error the client raises (FileNotFoundError, …)
        assert name in tacmesh.__all__, f"python/README.md names {name}, not in tacmesh.__all__"
        exported = getattr(package, name, None)
        assert exported is not None, f"python/README.md names {name}: `from tacmesh import` fails"


def test_the_readme_names_every_error_class_and_all_are_exported() -> None:
    errors = package_errors()
    assert {
        "WireError",
        "InvalidNumber",
        "StreamEndedInFrame",
        "UntrustedServer",
    } <= errors
    named = set(named_classes(README.read_text(encoding="utf-8")))
    assert errors <= named, f"python/README.md does not name {sorted(errors - named)}"
    assert errors <= set(tacmesh.__all__), f"not exported: {sorted(errors - set(tacmesh.__all__))}"
    for name in errors:
        exported = getattr(tacmesh, name)
        assert exported is getattr(wire, name, None) or exported is getattr(subscriber, name)
    # The old name is the same class.
    assert tacmesh.ProtocolError is tacmesh.WireError
    assert issubclass(tacmesh.InvalidNumber, tacmesh.WireError)
    assert issubclass(tacmesh.UntrustedServer, ConnectionError)


def test_all_names_what_the_package_has_once_each() -> None:
    assert len(tacmesh.__all__) == len(set(tacmesh.__all__)), "a name twice in __all__"
    missing = [name for name in tacmesh.__all__ if not hasattr(tacmesh, name)]
    assert not missing, f"in __all__, not in the package: {missing}"
    # Everything imported into the package (its submodules aside) is in __all__.
    public = {
        name
        for name, value in vars(tacmesh).items()
        if not name.startswith("_") and not isinstance(value, type(tacmesh))
    }
    assert public == set(tacmesh.__all__), public ^ set(tacmesh.__all__)
