"""The one exception type for anything a user can get wrong."""


class VolclError(Exception):
    """A user-caused problem: bad scene, missing file, unknown device.

    The message names where (file, line, element), what was found, and what is allowed.
    """

    def __init__(self, message, file=None, line=None, element=None):
        where = ""
        if file is not None:
            where = str(file)
            if line is not None:
                where += f":{line}"
            if element is not None:
                where += f": <{element}>"
            where += ": "
        super().__init__(where + message)
        self.file, self.line, self.element = file, line, element
