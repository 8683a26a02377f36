"""A second MCAP reader, written from the format's specification (mcap.dev/spec), not the mcap package.

Enough of the spec to check a file endocal wrote as another tool (Foxglove, PlotJuggler) would
meet it: the magic at both ends, records by opcode, chunks decompressed (zstd, lz4 or none) and
their CRC-32 checked, schemas, channels, messages and metadata decoded.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
OP_METADATA, OP_DATA_END = 0x0C, 0x0F


@dataclass
class SpecFile:
    profile: str = ""
    library: str = ""
    schemas: dict = field(default_factory=dict)  # id -> (name, encoding, data)
    channels: dict = field(default_factory=dict)  # id -> (schema_id, topic, message_encoding)
    messages: list = field(default_factory=list)  # (channel_id, sequence, log_time, data)
    metadata: dict = field(default_factory=dict)  # name -> {key: value}
    chunks: int = 0


class _Buf:
    def __init__(self, data: bytes):
        self.data, self.pos = data, 0

    def take(self, n: int) -> bytes:
        out = self.data[self.pos:self.pos + n]
        if len(out) != n:
            raise ValueError(f"record cut short at byte {self.pos}")
        self.pos += n
        return out

    def u16(self) -> int:
        return struct.unpack("<H", self.take(2))[0]

    def u32(self) -> int:
        return struct.unpack("<I", self.take(4))[0]

    def u64(self) -> int:
        return struct.unpack("<Q", self.take(8))[0]

    def string(self) -> str:
        return self.take(self.u32()).decode("utf-8")

    def string_map(self) -> dict:
        end = self.u32() + self.pos
        out = {}
        while self.pos < end:
            k = self.string()
            out[k] = self.string()
        return out

    def done(self) -> bool:
        return self.pos >= len(self.data)


def _decompress(kind: str, data: bytes, size: int) -> bytes:
    if kind == "":
        return data
    if kind == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if kind == "lz4":
        import lz4.frame

        return lz4.frame.decompress(data)
    raise ValueError(f"unknown chunk compression {kind!r}")


def _records(buf: _Buf, out: SpecFile, in_chunk: bool) -> None:
    while not buf.done():
        op = buf.take(1)[0]
        body = _Buf(buf.take(buf.u64()))
        if op == OP_HEADER:
            out.profile, out.library = body.string(), body.string()
        elif op == OP_SCHEMA:
            sid, name, enc = body.u16(), body.string(), body.string()
            out.schemas[sid] = (name, enc, body.take(body.u32()))
        elif op == OP_CHANNEL:
            cid, sid, topic, enc = body.u16(), body.u16(), body.string(), body.string()
            body.string_map()
            out.channels[cid] = (sid, topic, enc)
        elif op == OP_MESSAGE:
            cid, seq, log_time, _publish = body.u16(), body.u32(), body.u64(), body.u64()
            out.messages.append((cid, seq, log_time, body.data[body.pos:]))
        elif op == OP_CHUNK and not in_chunk:
            body.u64(), body.u64()  # message start and end time
            size, crc, kind = body.u64(), body.u32(), body.string()
            records = _decompress(kind, body.take(body.u64()), size)
            if len(records) != size or (crc and zlib.crc32(records) != crc):
                raise ValueError(f"chunk {out.chunks}: size or CRC-32 does not match")
            out.chunks += 1
            _records(_Buf(records), out, in_chunk=True)
        elif op == OP_METADATA:
            name = body.string()
            out.metadata[name] = body.string_map()
        elif op == OP_FOOTER:
            return
        # other records (indexes, statistics, summary offsets, data end) are not needed to read the data


def read_spec(data: bytes) -> SpecFile:
    """Every schema, channel, message and metadata record of an MCAP file's bytes."""
    if not (data.startswith(MAGIC) and data.endswith(MAGIC)):
        raise ValueError("not an MCAP file: the magic is missing at its start or end (a file cut short?)")
    out = SpecFile()
    _records(_Buf(data[len(MAGIC):-len(MAGIC)]), out, in_chunk=False)
    return out
