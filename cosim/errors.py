"""The one error type a user sees for bad input, and its exit code."""

EXIT_BAD_INPUT = 2


class CaseError(Exception):
    """Bad case input: names the file, the key, the value and what is allowed.

    Raised before any computation starts; the CLI prints it and exits with
    ``EXIT_BAD_INPUT``.
    """

    def __init__(self, file, key, value, allowed):
        self.file, self.key, self.value, self.allowed = str(file), key, value, allowed
        super().__init__(f"{self.file}: key '{key}' = {value!r}: {allowed}")
