"""The one exception type for bad input.

Every check on user-supplied data (files, command-line values, point sets handed to the library) raises
`InputError` with a message a user can act on. The command line turns it into one stderr line and exit code 2.
"""


class InputError(ValueError):
    """Bad input: the message says what is wrong and, where it can, where and how to fix it."""
