class CaraError(Exception):
    """A user-facing error: names the file (if any) and what is wrong. Never shown as a traceback."""
    def __init__(self, message: str, path: str | None = None):
        self.path = str(path) if path is not None else None
        super().__init__(f"{self.path}: {message}" if self.path else message)
