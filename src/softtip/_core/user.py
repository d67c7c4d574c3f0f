"""The user's own: the folders softtip keeps files in, and the settings file that chooses the
toolkit's defaults.

A command's defaults (the design ``simulate`` takes, the scenario ``live --emulate`` plays, what plain
``softtip demo`` runs) are softtip's own systems' unless the user's settings file chooses a system,
whose offered defaults (:attr:`softtip._core.systems.System.defaults`) then come first::

    [defaults]
    system = "springtip"

The file is ``SOFTTIP_CONFIG`` if set, else ``softtip/config.toml`` in the XDG config folder; without
it nothing is read (and the config reader is not imported).
"""

from __future__ import annotations

import os
from pathlib import Path


def user_folder(xdg_variable: str, fallback: str, error: type[ValueError], override: str) -> Path:
    """``softtip`` in the XDG folder ``xdg_variable`` names (if an absolute path, else ``~/fallback``).
    An empty or relative ``HOME`` falls back to the user's home in the password database, as XDG readers
    do; a home that is the filesystem root (no home at all) raises ``error`` naming ``override``, the
    variable that chooses the folder instead."""
    xdg = os.environ.get(xdg_variable, "")
    if os.path.isabs(xdg):
        return Path(xdg) / "softtip"
    home = os.environ.get("HOME", "")
    if not os.path.isabs(home):
        try:
            import pwd

            home = pwd.getpwuid(os.getuid()).pw_dir
        except (ImportError, KeyError):  # no password database, or a user id without an entry (containers)
            home = ""
    if not os.path.isabs(home) or Path(home) == Path(home).parent:
        raise error(f"HOME = {os.environ.get('HOME', '')!r}: no home folder to keep the {fallback.strip('.')} in; "
                    f"set {override} (or {xdg_variable}) to a folder")
    return Path(home) / fallback / "softtip"


def settings_file() -> Path | None:
    """The user's settings file, if there is one."""
    chosen = os.environ.get("SOFTTIP_CONFIG")
    if chosen:
        return Path(chosen)  # named: a missing file is refused when read
    try:
        path = user_folder("XDG_CONFIG_HOME", ".config", ValueError, "SOFTTIP_CONFIG") / "config.toml"
    except ValueError:  # no home: no settings
        return None
    return path if path.is_file() else None


def chosen_system(registered: list[str]) -> str | None:
    """The system the user's settings choose for the defaults, one of ``registered``; a settings file
    that is not TOML, has other keys or names no registered system is refused in one line."""
    path = settings_file()
    if path is None:
        return None
    from softtip._core.config import parse, read_toml, refused
    from softtip._core.user_settings import Settings

    settings = parse(Settings, read_toml(path, "softtip settings"), str(path))
    system = settings.defaults.system
    if system is not None and system not in registered:
        raise refused(f"expected a registered system: {', '.join(registered)}", str(path), "defaults", "system",
                      value=system)
    return system
