"""The error types: bad input (a file, a key path, what was found and what was expected) and an
output that could not be written. Commands turn an InputError into exit status 2, an OutputError into 1.
"""


class InputError(Exception):
    """Bad input from the user: a malformed file, an unknown key, an impossible value.

    ``str(err)`` reads ``FILE: KEY: MESSAGE`` (file and key omitted when unknown).
    """

    def __init__(self, message: str, *, file: str | None = None, key: str | None = None):
        self.file = file
        self.key = key
        self.message = message
        parts = [p for p in (file, key) if p]
        super().__init__(": ".join(parts + [message]))

    def in_file(self, file: str) -> "InputError":
        """The same error, naming ``file`` when it did not name one yet."""
        if self.file:
            return self
        return InputError(self.message, file=file, key=self.key)


class OutputError(Exception):
    """An output could not be written (a full disk, any OS error): exit status 1, not 2.

    ``str(err)`` reads ``FILE: MESSAGE``, e.g. ``m.h5: no space left on device``.
    """

    def __init__(self, message: str, *, file: str | None = None):
        self.file = file
        self.message = message
        super().__init__(f"{file}: {message}" if file else message)
