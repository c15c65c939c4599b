"""A client for the tacmesh daemon: its meshes as typed messages with numpy arrays.

See README.md beside this package, and docs/protocol.md in the repository for the wire format.
"""

from .subscriber import Refused, Scene, SceneObject, Subscriber, VersionMismatch
from .wire import (
    FIRST_PLANE_ID,
    SUPPORTED_VERSIONS,
    FrameDecoder,
    Goodbye,
    Hello,
    Message,
    ProtocolError,
    Remove,
    SnapshotDone,
    StageLatency,
    Stats,
    Upsert,
)

__all__ = [
    "FIRST_PLANE_ID",
    "SUPPORTED_VERSIONS",
    "FrameDecoder",
    "Goodbye",
    "Hello",
    "Message",
    "ProtocolError",
    "Refused",
    "Remove",
    "Scene",
    "SceneObject",
    "SnapshotDone",
    "StageLatency",
    "Stats",
    "Subscriber",
    "Upsert",
    "VersionMismatch",
]
