"""Dynamixel Protocol 2.0 on the wire: CRC-16, byte stuffing, instruction and status packets.

Pure functions and a stream parser, no I/O (ROBOTIS e-manual, "Protocol 2.0"):

``FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAM... | CRC_L CRC_H``

``LEN`` counts the instruction, the parameters and the CRC (after stuffing). Stuffing: in
everything after the length field, each ``FF FF FD`` is followed by an extra ``FD``, so the
header pattern never appears inside a packet. The CRC-16 (polynomial 0x8005, initial 0, no
reflection) runs over the whole stuffed packet from the first header byte to the last
parameter. A status packet has instruction ``0x55`` and an error byte before its parameters:
bit 7 is the hardware alert, bits 0-6 the error number of the instruction.
"""

from __future__ import annotations

from dataclasses import dataclass

HEADER = bytes((0xFF, 0xFF, 0xFD, 0x00))
BROADCAST_ID = 0xFE
STATUS = 0x55

PING, READ, WRITE, REG_WRITE, ACTION, FACTORY_RESET, REBOOT, CLEAR = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x08, 0x10
SYNC_READ, SYNC_WRITE, FAST_SYNC_READ, BULK_READ, BULK_WRITE = 0x82, 0x83, 0x8A, 0x92, 0x93

# error numbers of the status packet (bits 0-6)
ERR_RESULT_FAIL, ERR_INSTRUCTION, ERR_CRC, ERR_DATA_RANGE, ERR_DATA_LENGTH, ERR_DATA_LIMIT, ERR_ACCESS = range(1, 8)
ERR_ALERT = 0x80


def _crc_table() -> list[int]:
    table = []
    for i in range(256):
        c = i << 8
        for _ in range(8):
            c = ((c << 1) ^ 0x8005) if c & 0x8000 else (c << 1)
        table.append(c & 0xFFFF)
    return table


_TABLE = _crc_table()


def crc16(data: bytes) -> int:
    """CRC-16/BUYPASS (polynomial 0x8005, initial 0) of ``data``, as Protocol 2.0 uses it."""
    crc = 0
    for b in data:
        crc = ((crc << 8) ^ _TABLE[((crc >> 8) ^ b) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    """Insert ``FD`` after every ``FF FF FD`` of the instruction and parameters."""
    out = bytearray()
    for b in body:
        out.append(b)
        if b == 0xFD and len(out) >= 3 and out[-3] == 0xFF and out[-2] == 0xFF:
            out.append(0xFD)
    return bytes(out)


def unstuff(body: bytes) -> bytes:
    """Remove the ``FD`` that :func:`stuff` inserted."""
    out = bytearray()
    i = 0
    while i < len(body):
        out.append(body[i])
        if body[i] == 0xFD and len(out) >= 3 and out[-3] == 0xFF and out[-2] == 0xFF \
                and i + 1 < len(body) and body[i + 1] == 0xFD:
            i += 1  # the stuffed FD
        i += 1
    return bytes(out)


def packet(dxl_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A complete, stuffed, CRC'd packet."""
    body = stuff(bytes((instruction,)) + bytes(params))
    length = len(body) + 2
    head = HEADER + bytes((dxl_id, length & 0xFF, length >> 8))
    crc = crc16(head + body)
    return head + body + bytes((crc & 0xFF, crc >> 8))


def status(dxl_id: int, error: int, params: bytes = b"") -> bytes:
    """A status packet (instruction 0x55) with its error byte."""
    return packet(dxl_id, STATUS, bytes((error,)) + bytes(params))


@dataclass(frozen=True)
class Instruction:
    """A parsed instruction packet (parameters unstuffed)."""

    id: int
    instruction: int
    params: bytes


class PacketParser:
    """Accumulates bytes from the bus and yields complete packets.

    Garbage before a header is skipped (a real servo resynchronises on the header the same
    way); a packet whose CRC does not match is dropped and counted in :attr:`crc_errors`
    (servos ignore it: the host times out).
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.crc_errors = 0

    def feed(self, data: bytes) -> list[Instruction]:
        self._buf.extend(data)
        out = []
        while True:
            start = self._buf.find(HEADER[:3])
            if start < 0:
                del self._buf[:-2]  # keep a possible split header
                return out
            del self._buf[:start]
            if len(self._buf) < 7:
                return out
            length = self._buf[5] | (self._buf[6] << 8)
            total = 7 + length
            if length < 3 or length > 1024:
                del self._buf[:3]
                continue
            if len(self._buf) < total:
                return out
            raw = bytes(self._buf[:total])
            del self._buf[:total]
            if crc16(raw[:-2]) != (raw[-2] | (raw[-1] << 8)):
                self.crc_errors += 1
                continue
            body = unstuff(raw[7:-2])
            out.append(Instruction(raw[4], body[0], body[1:]))
