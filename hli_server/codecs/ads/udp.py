"""ADS over UDP (port 48899): the discovery answer and AddRoute, sans-I/O (H-04, docs/ads.md).

What a TwinCAT system answers on UDP 48899 (TwinCAT's "Broadcast Search", ``pyads.add_route_to_plc``,
``pyads.ads.get_net_id`` / ``adsGetNetIdForPLC``, Beckhoff AdsLib's ``AddRemoteRoute`` and
``GetRemoteAddress``). All integers little-endian::

    | cookie u32 = 0x71146603 | invoke id u32 | service u32 |        service: 1 server info (discovery),
    | AMS NetId (6) | AMS port u16 |                                  6 add route; | 0x80000000 = response
    | tag count u32 | tag ... |
    tag: | tag id u16 | length u16 | data (length) |

    Tags (AdsLib ``UdpTag``, what pyads sends and what TwinCAT answers):
      1  status (u32 ADS error code; the AddRoute response's only tag; 0 = route added)
      2  password (text, NUL-terminated)          3  TwinCAT version: major u8, minor u8, build u16
      4  OS version (OSVERSIONINFO: size, major, minor, build, platform id u32, then 128 UTF-16 chars)
      5  computer name (text; the host name in a discovery answer, the route's address in AddRoute)
      7  AMS NetId (6 bytes)                      12 route name (text)
      13 user name (text)                         18 fingerprint (text, TwinCAT 3.1.4024 and newer)

A discovery request carries no tags (pyads sends NetId 1.1.1.1.1.1, port 10000). The answer's AMS
address is the server's NetId and port 10000, then the host name, the OS version, the TwinCAT
version (and optionally a fingerprint). An AddRoute request carries route name, NetId, user name,
password and computer name, in that order as pyads and AdsLib send them; the answer carries the
status alone: 0, or 0x704 (``ADSERR_DEVICE_INVALIDACCESS``) for credentials TwinCAT does not accept
(the code reported by AdsLib's ``AddRemoteRoute``; pyads 3.6 reads the bytes one place off and
raises ``RuntimeError("Unexpected response from PLC")`` for it, pyads issue #460).

Texts are NUL-terminated; TwinCAT sends Windows-1252, pyads UTF-8: the codec decodes UTF-8 and
falls back to Windows-1252. Every length is checked against the datagram; anything that does not
parse raises :class:`~hli_server.codecs.ads.errors.AdsCodecError` (the door drops such a datagram:
UDP has no error reply).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum
from typing import Final

from hli_server.codecs.ads.errors import AdsCodecError
from hli_server.codecs.ads.frames import NetId

__all__ = [
    "MAX_UDP_TAGS",
    "UDP_COOKIE",
    "AddRouteRequest",
    "UdpMessage",
    "UdpService",
    "UdpTag",
    "decode_udp",
    "encode_add_route_reply",
    "encode_discovery_reply",
    "encode_udp",
    "os_version_tag",
]

UDP_COOKIE: Final = 0x71146603
MAX_UDP_TAGS: Final = 64
"""More tags than this in one datagram are refused (TwinCAT's requests carry at most a dozen)."""
SYSTEM_SERVICE_PORT: Final = 10000

_HEAD: Final = struct.Struct("<III6sHI")
_TAG: Final = struct.Struct("<HH")
_U32: Final = struct.Struct("<I")
_VERSION: Final = struct.Struct("<BBH")
_OS_VERSION: Final = struct.Struct("<5I")


class UdpService(IntEnum):
    SERVER_INFO = 1
    """Discovery ("Broadcast Search"): who are you (NetId, host name, versions)."""
    ADD_ROUTE = 6
    """Add a route to the sender (credentials in the tags)."""
    RESPONSE = 0x8000_0000
    """Or-ed into the service of a response."""


class UdpTag(IntEnum):
    STATUS = 1
    PASSWORD = 2
    TC_VERSION = 3
    OS_VERSION = 4
    COMPUTER_NAME = 5
    NET_ID = 7
    ROUTE_NAME = 12
    USER_NAME = 13
    FINGERPRINT = 18


@dataclass(frozen=True, slots=True)
class UdpMessage:
    """One ADS/UDP datagram: header, AMS address and the tags in the order sent."""

    invoke_id: int
    service: int
    net_id: NetId
    port: int
    tags: tuple[tuple[int, bytes], ...] = ()

    @property
    def is_response(self) -> bool:
        return bool(self.service & UdpService.RESPONSE)

    def tag(self, tag: int) -> bytes | None:
        """The data of the first tag ``tag``, or None."""
        for t, data in self.tags:
            if t == tag:
                return data
        return None


def decode_udp(data: bytes) -> UdpMessage:
    """One datagram; raises :class:`AdsCodecError` naming what does not parse."""
    if len(data) < _HEAD.size:
        raise AdsCodecError(f"ADS/UDP datagram of {len(data)} bytes: the header alone is {_HEAD.size}")
    cookie, invoke, service, net_id, port, count = _HEAD.unpack_from(data)
    if cookie != UDP_COOKIE:
        raise AdsCodecError(f"ADS/UDP cookie 0x{cookie:08X} is not 0x{UDP_COOKIE:08X}: not ADS over UDP")
    if count > MAX_UDP_TAGS:
        raise AdsCodecError(f"ADS/UDP datagram announces {count} tags, at most {MAX_UDP_TAGS} are read")
    pos = _HEAD.size
    tags: list[tuple[int, bytes]] = []
    for i in range(count):
        if len(data) - pos < _TAG.size:
            raise AdsCodecError(f"ADS/UDP tag {i} of {count}: its header runs past the datagram's end")
        tag, length = _TAG.unpack_from(data, pos)
        pos += _TAG.size
        if len(data) - pos < length:
            raise AdsCodecError(
                f"ADS/UDP tag {i} (id {tag}) of {length} bytes runs past the datagram's end "
                f"({len(data)} bytes)"
            )
        tags.append((tag, bytes(data[pos : pos + length])))
        pos += length
    return UdpMessage(invoke, service, NetId(net_id), port, tuple(tags))


def encode_udp(message: UdpMessage) -> bytes:
    parts = [
        _HEAD.pack(
            UDP_COOKIE,
            message.invoke_id,
            message.service,
            bytes(message.net_id),
            message.port,
            len(message.tags),
        )
    ]
    for tag, data in message.tags:
        if len(data) > 0xFFFF:
            raise ValueError(f"ADS/UDP tag {tag} of {len(data)} bytes: at most 65535")
        parts.append(_TAG.pack(tag, len(data)))
        parts.append(data)
    return b"".join(parts)


def _text(data: bytes) -> str:
    raw = data.split(b"\0", 1)[0]
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("cp1252", "replace")


def _text_tag(text: str) -> bytes:
    return text.encode("utf-8") + b"\0"


@dataclass(frozen=True, slots=True)
class AddRouteRequest:
    """The tags of an AddRoute request, decoded (:meth:`from_message`)."""

    route_name: str
    net_id: NetId
    """the NetId the route is for (pyads' ``added_net_id``, by default its ``sending_net_id``)"""
    address: str
    """where that NetId lives: an IP address or a host name (pyads' ``adding_host_name``)"""
    user: str | None
    password: str | None
    """None when the request carries no plain-text password (newer TwinCAT engineering sends it hashed)"""

    @classmethod
    def from_message(cls, message: UdpMessage) -> AddRouteRequest:
        raw_net_id = message.tag(UdpTag.NET_ID)
        if raw_net_id is None or len(raw_net_id) != 6:
            raise AdsCodecError("ADS/UDP AddRoute without a 6-byte AMS NetId tag (7)")
        address = message.tag(UdpTag.COMPUTER_NAME)
        if address is None:
            raise AdsCodecError("ADS/UDP AddRoute without the route's address (computer name tag 5)")
        name = message.tag(UdpTag.ROUTE_NAME)
        user = message.tag(UdpTag.USER_NAME)
        password = message.tag(UdpTag.PASSWORD)
        host = _text(address).strip()
        if not host:
            raise AdsCodecError("ADS/UDP AddRoute with an empty address (computer name tag 5)")
        return cls(
            route_name=_text(name).strip() if name is not None else host,
            net_id=NetId(raw_net_id),
            address=host,
            user=_text(user) if user is not None else None,
            password=_text(password) if password is not None else None,
        )


def os_version_tag(major: int, minor: int, build: int, platform_id: int, text: str) -> bytes:
    """Tag 4: an OSVERSIONINFO (its size 276, the numbers, 128 UTF-16 characters of service-pack text)."""
    chars = text.encode("utf-16-le")[: 127 * 2]
    return _OS_VERSION.pack(276, major, minor, build, platform_id) + chars.ljust(256, b"\0")


def encode_discovery_reply(
    request: UdpMessage,
    net_id: NetId,
    host_name: str,
    tc_version: tuple[int, int, int],
    os_version: bytes,
    fingerprint: str | None = None,
) -> bytes:
    """The answer to a server-info request: our NetId (port 10000), host name, OS and TwinCAT version."""
    tags = [
        (int(UdpTag.COMPUTER_NAME), _text_tag(host_name)),
        (int(UdpTag.OS_VERSION), os_version),
        (int(UdpTag.TC_VERSION), _VERSION.pack(*tc_version)),
    ]
    if fingerprint is not None:
        tags.append((int(UdpTag.FINGERPRINT), _text_tag(fingerprint)))
    return encode_udp(
        UdpMessage(
            request.invoke_id,
            UdpService.SERVER_INFO | UdpService.RESPONSE,
            net_id,
            SYSTEM_SERVICE_PORT,
            tuple(tags),
        )
    )


def encode_add_route_reply(request: UdpMessage, net_id: NetId, status: int) -> bytes:
    """The answer to AddRoute: our NetId (port 10000) and the status tag (0 or an ADS error code)."""
    return encode_udp(
        UdpMessage(
            request.invoke_id,
            UdpService.ADD_ROUTE | UdpService.RESPONSE,
            net_id,
            SYSTEM_SERVICE_PORT,
            ((int(UdpTag.STATUS), _U32.pack(status)),),
        )
    )
