"""The one exception type for bad user input: the CLI prints its message as one line."""


class UserError(ValueError):
    """Bad input from a user: says what was wrong and what would be right."""
