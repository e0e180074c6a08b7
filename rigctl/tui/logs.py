"""Log records into the shoot UI, not onto the terminal. While the UI runs, the root logger's handlers (the
CLI's stderr handler among them, which holds the terminal itself) are set aside and one handler posts every
record to the app as a message: thread-safe and never blocking, so a capture or writer thread that logs never
waits on the screen and never writes over it. Python warnings go the same way. Everything is put back as it
was when the UI ends."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

from textual.message import Message


class LogRecordPosted(Message):
    """One formatted log record for the screen."""

    def __init__(self, level: int, text: str) -> None:
        super().__init__()
        self.level = level
        self.text = text


class PostingHandler(logging.Handler):
    """Formats a record and hands it to ``post`` (the app's ``post_message``, safe from any thread)."""

    def __init__(self, post: Callable[[Message], object], level: int = logging.NOTSET) -> None:
        super().__init__(level)
        self.post = post
        self.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.post(LogRecordPosted(record.levelno, self.format(record)))
        except Exception:  # the app is gone: a record then is not worth a traceback on the terminal
            self.handleError(record)


@dataclass
class RoutedLogging:
    """The root logger routed into the UI between :meth:`install` and :meth:`restore`."""

    handler: PostingHandler
    saved_handlers: list[logging.Handler]
    captured_warnings: bool

    @classmethod
    def install(cls, post: Callable[[Message], object]) -> RoutedLogging:
        root = logging.getLogger()
        handler = PostingHandler(post)
        routed = cls(handler, list(root.handlers), _capturing_warnings())
        for h in routed.saved_handlers:
            root.removeHandler(h)
        root.addHandler(handler)  # the root logger's level stays what it was (WARNING unless --debug)
        logging.captureWarnings(True)
        return routed

    def restore(self) -> None:
        root = logging.getLogger()
        root.removeHandler(self.handler)
        for h in self.saved_handlers:
            root.addHandler(h)
        logging.captureWarnings(self.captured_warnings)


def _capturing_warnings() -> bool:
    return getattr(logging, "_warnings_showwarning", None) is not None
