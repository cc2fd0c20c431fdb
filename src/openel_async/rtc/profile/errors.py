"""The one error raised for bad RTC Profile documents, and the limits both forms share."""

from __future__ import annotations

from ...positioned import DocumentError, Location

# One budget for both forms (YAML: nodes after alias expansion, keys included; XML:
# elements and attributes, each attribute counting as a key and a value).  Writers
# check the same budget, so a file this library wrote always loads again.
# The depth is that of the document tree (a constraint level takes about three), so
# any constraint within the constraint module's own depth limit fits in both forms.
MAX_NODES = 2_000_000
MAX_DEPTH = 256


class ProfileError(DocumentError):
    """A profile document is malformed, unsafe or invalid.

    ``path`` names the offending field in YAML key terms (the same logical path is used
    for XML documents), e.g. ``rtcProfile.configurationSet.configuration[2].defaultValue``;
    it is ``<document>`` for errors of the document as a whole.  ``location`` (file,
    line, column; None for a profile built in code) says where the field is written when
    the profile was read from text; ``str()`` then starts with ``FILE:LINE:COL:``.
    """

    def __init__(self, path: str, message: str, *, location: Location | None = None) -> None:
        super().__init__(message, path=path, location=location)
        text = f"{path}: {message}" if path else message
        self.args = (f"{location}: {text}" if location is not None else text,)

    def at(self, location: Location | None) -> ProfileError:
        """This error with ``location`` (itself when it has one, or ``location`` is None)."""
        if self.location is not None or location is None:
            return self
        return ProfileError(self.path, self.message, location=location)
