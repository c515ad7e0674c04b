"""The winder's CAN bus: ODrive CAN Simple (firmware 0.6 generation) plus the winch sensors.

Shared by the plant (which *is* the ODrive axis and the winch sensors) and the ground
station (the CAN host); pure byte-level encoding, no bus access. One module per concern,
all their public names here:

- :mod:`.ids`: node and command ids, the frame id's layout, the enums (axis states, control
  and input modes, error and flag bits), :class:`~.ids.Frame` and :class:`~.ids.CanFrameError`;
- :mod:`.codec`: per message its decoded record, its encoder and its decoder;
- :mod:`.messages`: the table of messages (id, node, direction, length, period, DBC signal
  names, codec), lookup by name or frame id, signals by name, and the DBC file
  (:func:`~.messages.dbc_path`).
"""

from tuavdefs.can_protocol import codec, ids, messages
from tuavdefs.can_protocol.codec import *  # noqa: F403
from tuavdefs.can_protocol.ids import *  # noqa: F403
from tuavdefs.can_protocol.messages import *  # noqa: F403

__all__ = [*ids.__all__, *codec.__all__, *messages.__all__]
