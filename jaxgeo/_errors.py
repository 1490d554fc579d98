"""The one exception type of the package."""


class JaxgeoError(ValueError):
    """Raised for bad input (mesh, points, options) and for paths that cannot be
    completed. The message names the problem and, where it helps, the indices."""
