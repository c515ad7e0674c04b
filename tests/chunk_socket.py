"""A socket that hands out pre-cut chunks of a stream, for feeding
:meth:`groundstation.winch_link.WinchLinkClient.poll` byte streams cut anywhere."""

from __future__ import annotations


class ChunkSocket:
    """``recv`` returns the next pre-cut chunk whatever size is asked; ``sendall`` drops."""

    def __init__(self, chunks: list[bytes]) -> None:
        self.chunks = chunks

    def recv(self, size: int) -> bytes:
        return self.chunks.pop(0)

    def sendall(self, data: bytes) -> None:
        pass
