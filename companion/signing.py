"""The vehicle's MAVLink 2 signing: one key for its ground-station links and its component
link, set at start from a key file or by ``SETUP_SIGNING``, kept in that file.

The ground-station links share one signing state (link id 0): the key, the outgoing
timestamp and the replay table of every stream heard, so a frame accepted on one link is
a replay on any other. The component link to the winch has its own (link id 1). A new
key is written to the key file by a thread of its own (the control loop never waits for
the disk). The rules of what is accepted are ``tuavdefs.signing``'s.
"""

from __future__ import annotations

from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2

from companion.param_protocol import FileWriter
from tuavdefs import signing as sg

#: The link ids the vehicle signs with: its ground-station links, its component link.
GCS_LINK_ID = 0
COMPONENT_LINK_ID = 1


class VehicleSigning:
    """The signing states of the vehicle's links, and the key's file.

    ``key`` the key to start with (None: signing off); ``key_file`` where a key set by
    ``SETUP_SIGNING`` is kept (None: nowhere)."""

    def __init__(self, key: bytes | None = None, key_file: Path | str | None = None) -> None:
        self.gcs = mavlink2.MAVLinkSigning()
        self.gcs.link_id = GCS_LINK_ID
        self.component = mavlink2.MAVLinkSigning()
        self.component.link_id = COMPONENT_LINK_ID
        self.key_file = Path(key_file) if key_file is not None else None
        self._writer: FileWriter | None = None
        self._apply(key, 0)

    @property
    def enabled(self) -> bool:
        """Whether the links sign and check."""
        return self.gcs.secret_key is not None

    @property
    def key(self) -> bytes | None:
        """The key in use (None: signing off)."""
        return self.gcs.secret_key

    def _apply(self, key: bytes | None, initial_timestamp: int) -> None:
        for state in (self.gcs, self.component):
            sg.set_key(state, key, initial_timestamp)

    def set_key(self, key: bytes | None, initial_timestamp: int = 0) -> None:
        """Use ``key`` from now on (None: signing off) on every link, and keep it in the
        key file (written off the control path)."""
        self._apply(key, initial_timestamp)
        if self.key_file is not None:
            if self._writer is None:
                self._writer = FileWriter(self.key_file)
            self._writer.submit(sg.key_file_text(key))

    def refresh(self) -> None:
        """Keep the outgoing timestamps at least the clock's (call about once a second)."""
        sg.refresh_timestamp(self.gcs)
        sg.refresh_timestamp(self.component)

    @property
    def refused(self) -> int:
        """Frames refused so far for a missing or bad signature or an old timestamp."""
        return self.gcs.reject_count + self.component.reject_count

    def write_errors(self) -> list[OSError]:
        """Failures to write the key file since the last call."""
        if self._writer is None or not self._writer.errors:
            return []
        errors, self._writer.errors = self._writer.errors, []
        return errors

    def close(self) -> None:
        """Write out a key still waiting."""
        if self._writer is not None:
            self._writer.close()
