"""The project's exception classes.

Every error caused by what a user passed in (a file, an array, an option) is an `InputError`; the
CLI turns it into one line on stderr and a non-zero exit status, never a traceback.
"""


class UaremeError(Exception):
    """Base class of every error this package raises on purpose."""


class InputError(UaremeError, ValueError):
    """Bad input from the user: wrong shape, dtype, value, or an unreadable file.

    The message names the problem and, where there is one, the file or the shape received.
    """


class ConfigError(InputError):
    """A configuration file or option that does not validate (unknown key, wrong type or unit)."""


class SourceError(UaremeError):
    """A source that failed while running: a camera that disconnected, a video that stopped decoding.

    Raised mid-stream (opening a bad source is an `InputError`); the pipeline keeps what it has
    written so far complete and valid, and exits with a non-zero status.
    """


class OutputError(UaremeError):
    """An output file that could not be written (disk full, quota, I/O error, read-only file system).

    A failing environment rather than a user mistake: the CLI exits 1, and the message names the file.
    """
