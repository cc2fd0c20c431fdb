"""The one error raised for bad RTC Profile documents."""

from __future__ import annotations


class ProfileError(ValueError):
    """A profile document is malformed, unsafe or invalid.

    ``path`` names the offending field in YAML key terms (the same logical path is used
    for XML documents), e.g. ``rtcProfile.configurationSet.configuration[2].defaultValue``;
    it is ``<document>`` for errors of the document as a whole.
    """

    def __init__(self, path: str, message: str) -> None:
        super().__init__(f"{path}: {message}" if path else message)
        self.path = path
        self.message = message
