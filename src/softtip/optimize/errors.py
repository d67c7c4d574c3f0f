"""The error of study files and study runs."""

from softtip._core.config import ConfigError


class StudyError(ConfigError):
    """A study file or setting that cannot describe a runnable study."""
