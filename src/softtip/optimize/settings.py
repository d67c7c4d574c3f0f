"""The study files' reader: the shared config reader, raising :class:`StudyError`."""

from __future__ import annotations

from softtip.settings import ConfigError
from softtip.settings import SettingsReader as _SettingsReader


class StudyError(ConfigError):
    """A study file or setting that cannot describe a runnable study."""


class SettingsReader(_SettingsReader):
    error = StudyError
