"""The base of errors a user can cause and fix.

Such an error's message is one sentence that names the thing (a file, a
parameter, a sensor) and says what to do. Commands and the GUI show the
message as it is, without a traceback.
"""


class UserError(ValueError):
    """A bad file, value or request from the user; the message says what to do."""
