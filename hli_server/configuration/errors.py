"""Configuration errors and where a value was set (file, line, key)."""

from __future__ import annotations

from dataclasses import dataclass


class ConfigError(Exception):
    """The configuration is invalid; ``messages`` holds every finding as ``file:line: key: text``,
    ``notes`` what the user should know besides (printed after them, not counted)."""

    def __init__(self, messages: list[str], notes: list[str] | None = None) -> None:
        self.messages = list(messages)
        self.notes = list(notes or [])
        super().__init__("\n".join([*self.messages, *self.notes]))


class ConfigFileError(ConfigError):
    """The machine file itself is missing or cannot be read (the CLI exits with 2)."""


@dataclass(frozen=True, slots=True)
class Origin:
    """Where a value was set: file, line and the key as written there."""

    file: str
    line: int
    key: str

    def where(self) -> str:
        return f"{self.file}:{self.line}: {self.key}" if self.key else f"{self.file}:{self.line}"
