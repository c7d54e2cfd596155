"""The one exception that means "bad input": the CLI maps it to exit code 2."""


class BadInput(ValueError):
    """Input that cannot be used as given; the message says what and how to fix it.

    The message is one line, shown to the user as is (no traceback).
    """
