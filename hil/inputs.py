"""What every command takes in before a schema is loaded: the error that bad input raises, and where a
named config or DBC file is found. Free of pydantic, so that parsing the arguments loads no schema."""

from __future__ import annotations

from pathlib import Path

SHIPPED = "hil.configs"  # the repository's configs/, installed with the package


class InputError(Exception):
    """Input that cannot be used (config, data, port, arguments): one line naming it and why, exit 2."""


class ConfigError(InputError, ValueError):
    """A configuration that cannot be used; the message names the key path and the reason."""


def resolve_path(path: str | Path) -> Path:
    """A config or DBC path as named in a config or a default: the path itself if it exists, else the shipped
    file of that name (``configs/NAME`` or ``NAME``), else the path unchanged so that its error names it."""
    path = Path(path)
    if path.exists() or path.parent not in (Path("."), Path("configs")):
        return path
    from importlib.resources import files  # with tempfile and zipfile: only for a name not found as given

    shipped = Path(files(SHIPPED) / path.name)  # an installed package is a directory
    return shipped if shipped.is_file() else path
