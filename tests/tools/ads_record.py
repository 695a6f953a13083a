"""Record the exact bytes real ADS clients send: the golden frames of ``tests/unit/test_ads_codec.py``.

Usage (from the repository root; Node's ``ads-client`` 2.x installed OUTSIDE the repository)::

    mkdir -p /tmp/nodeads && (cd /tmp/nodeads && npm init -y && npm install ads-client@2)
    .venv/bin/python tests/tools/ads_record.py --node-dir /tmp/nodeads --out tests/data/ads_golden_frames.json

A throwaway AMS/TCP listener on 127.0.0.1 (a free port) logs every frame a client sends and answers
it with a reply built here by hand with :mod:`struct` (deliberately NOT with the codec under test),
plausible enough that the client goes on to its next request. pyads (AdsLib) is driven in this
process, one labelled operation after the other; Node's ``ads-client`` runs once per operation in a
child process, so each connection carries one label. The replies are stored too: that the client
accepted them (it went on, no error) makes them known-good replies for the encoder.

This is a tool, not a test and not the server: it uses a thread per connection and blocking sockets
because it only ever serves one client at a time.
"""

from __future__ import annotations

import argparse
import json
import queue
import socket
import struct
import subprocess
import sys
import threading
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

_SYMBOLS = {
    # name: (index group, index offset, size, ADS data type, type name)
    "MAIN.counter": (0x4040, 0x1000, 4, 3, "DINT"),
    "MAIN.speed": (0x4040, 0x1008, 8, 5, "LREAL"),
    "MAIN.flag": (0x4040, 0x1010, 1, 33, "BOOL"),
}
NOTIFICATION_DELAY = 0.05  # s after the add reply: AdsLib registers its dispatcher only after reading it
NOTIFIED_DINT = 4242
NOTIFIED_LREAL = 2.5
NOTIFIED_FILETIME = 133_485_408_000_000_000  # 2024-01-01T00:00:00Z in 100 ns since 1601-01-01
_LOCAL_NET_ID = bytes((192, 168, 1, 50, 1, 1))  # what we assign on 0x1000 port connect


def _symbol_entry(name: str) -> bytes:
    group, offset, size, data_type, type_name = _SYMBOLS.get(name, (0x4040, 0x2000, 4, 3, "DINT"))
    comment = b""
    flags = 0  # no type GUID, no attributes: the entry ends after the comment
    body = struct.pack(
        "<IIIIHHHHH", group, offset, size, data_type, flags, 0, len(name), len(type_name), len(comment)
    )
    body += name.encode() + b"\0" + type_name.encode() + b"\0" + comment + b"\0"
    return struct.pack("<I", 4 + len(body)) + body


class Recorder:
    """Listens, logs every frame under the current label, answers by hand."""

    def __init__(self) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.label = "unlabelled"
        self.frames: list[dict[str, Any]] = []
        self._lock = threading.Lock()
        self._handle = 0x1234
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            conn, _ = self.listener.accept()
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _log(self, direction: str, data: bytes) -> None:
        with self._lock:
            self.frames.append({"label": self.label, "direction": direction, "hex": data.hex()})

    def _serve(self, conn: socket.socket) -> None:
        buf = b""
        send_lock = threading.Lock()
        with conn:
            while True:
                try:
                    chunk = conn.recv(65536)
                except OSError:
                    return
                if not chunk:
                    return
                buf += chunk
                while len(buf) >= 6:
                    length = struct.unpack_from("<I", buf, 2)[0]
                    if len(buf) < 6 + length:
                        break
                    frame, buf = buf[: 6 + length], buf[6 + length :]
                    self._log("client->server", frame)
                    reply = self._reply(frame)
                    if reply:
                        self._log("server->client", reply)
                        with send_lock:
                            conn.sendall(reply)
                    if reply and frame[22:24] == b"\x06\x00":  # AddDeviceNotification answered
                        sample = self._notification(frame, reply)
                        timer = threading.Timer(NOTIFICATION_DELAY, self._send, (conn, send_lock, sample))
                        timer.start()

    def _send(self, conn: socket.socket, send_lock: threading.Lock, data: bytes) -> None:
        self._log("server->client", data)
        with send_lock:
            conn.sendall(data)

    def _notification(self, request: bytes, reply: bytes) -> bytes:
        """A DeviceNotification (command 8, state flags 0x0004): one stamp, one sample of the added handle."""
        group, _, size = struct.unpack_from("<III", request, 38)
        handle = struct.unpack_from("<I", reply, 42)[0]
        if group == 0xF100:  # ADS state (ads-client's connection watch): RUN
            value = struct.pack("<HH", 5, 0)
        elif group == 0xF008:  # symbol version
            value = b"\x01"
        elif size == 4:
            value = struct.pack("<i", NOTIFIED_DINT)
        else:
            value = struct.pack("<d", NOTIFIED_LREAL)
        sample = struct.pack("<II", handle, len(value)) + value
        stamp = struct.pack("<QI", NOTIFIED_FILETIME, 1) + sample
        stream = struct.pack("<I", 4 + len(stamp)) + struct.pack("<I", 1) + stamp
        header = request[14:22] + request[6:14] + struct.pack("<HHIII", 8, 0x0004, len(stream), 0, 0)
        return struct.pack("<HI", 0, len(header) + len(stream)) + header + stream

    def _reply(self, frame: bytes) -> bytes:
        reserved = struct.unpack_from("<H", frame)[0]
        if reserved == 0x1000:  # port connect: assign a NetId and the requested (or a free) port
            port = struct.unpack_from("<H", frame, 6)[0] or 32905
            return struct.pack("<HI", 0x1000, 8) + _LOCAL_NET_ID + struct.pack("<H", port)
        if reserved == 0x0001:  # port close: echo
            return frame
        if reserved != 0:
            return b""
        target, source = frame[6:14], frame[14:22]
        cmd, _flags, _length, _error, invoke = struct.unpack_from("<HHIII", frame, 22)
        data = frame[38:]
        payload = self._payload(cmd, data)
        if payload is None:
            return b""
        header = source + target + struct.pack("<HHIII", cmd, 0x0005, len(payload), 0, invoke)
        return struct.pack("<HI", 0, len(header) + len(payload)) + header + payload

    def _payload(self, cmd: int, data: bytes) -> bytes | None:
        ok = struct.pack("<I", 0)
        if cmd == 1:
            return ok + struct.pack("<BBH", 3, 1, 4024) + b"Plc30 App".ljust(16, b"\0")
        if cmd == 2:
            group, offset, length = struct.unpack_from("<III", data)
            if group == 0xF0:  # TwinCAT system state on port 10000: RUN, then zeros
                body = struct.pack("<HH", 5, 0) + bytes(12)
            elif group == 0xF00F:  # upload info 2: 24 bytes (a TwinCAT 3.1 4022 answer)
                body = struct.pack("<6I", 3, 300, 2, 200, 0, 0)[:length]
            elif group == 0xF00C:
                body = struct.pack("<2I", 3, 300)[:length]
            elif group == 0xF008:
                body = b"\x01"[:length]
            else:
                body = bytes(length)
            return ok + struct.pack("<I", len(body)) + body
        if cmd in (3, 5):
            return ok
        if cmd == 4:
            return ok + struct.pack("<HH", 5, 0)
        if cmd == 6:
            self._handle += 1
            return ok + struct.pack("<I", self._handle)
        if cmd == 7:
            return ok
        if cmd == 9:
            group, offset, read_len, write_len = struct.unpack_from("<IIII", data)
            write = data[16 : 16 + write_len]
            if group == 0xF003:
                self._handle += 1
                body = struct.pack("<I", self._handle)
                if read_len > 4:  # ads-client asks 0xFFFFFFFF: handle, size, type decoration, type name
                    name = write.rstrip(b"\0").decode()
                    _, _, size, _, type_name = _SYMBOLS.get(name, (0, 0, 4, 3, "DINT"))
                    body += struct.pack("<IIH", size, 0, len(type_name)) + type_name.encode() + b"\0"
            elif group == 0xF009:
                body = _symbol_entry(write.rstrip(b"\0").decode())
            elif group == 0xF011:  # data type by name: "not found" -> clients use built-in base types
                return struct.pack("<II", 0x710, 0)
            elif group == 0xF080:
                sizes = [struct.unpack_from("<III", write, 12 * i)[2] for i in range(offset)]
                body = bytes(4 * offset) + bytes(sum(sizes))
            elif group == 0xF081:
                body = bytes(4 * offset)
            elif group == 0xF082:
                sizes = [struct.unpack_from("<IIII", write, 16 * i)[2] for i in range(offset)]
                body = b"".join(struct.pack("<II", 0, s) for s in sizes) + bytes(sum(sizes))
            else:
                body = bytes(min(read_len, 64))
            return ok + struct.pack("<I", len(body)) + body
        return None


def _check_notification(value: Any, expected: Any, stamp: Any) -> None:
    """The client decoded the hand-built DeviceNotification to the value and time it carries."""
    when = datetime(2024, 1, 1, tzinfo=UTC)
    if value != expected or stamp.replace(tzinfo=UTC) != when:
        raise SystemExit(f"notification decoded as {value!r} at {stamp!r}, sent {expected!r} at {when}")


def record_pyads(rec: Recorder) -> str:
    import pyads

    pyads.open_port()
    pyads.set_local_address("10.1.2.3.1.1")
    conn = pyads.Connection("127.0.0.1.1.1", 851, f"127.0.0.1:{rec.port}")
    conn.set_timeout(2000)
    conn.open()

    def op(label: str, fn: Any, *args: Any, **kwargs: Any) -> None:
        rec.label = label
        fn(*args, **kwargs)

    op("read_device_info", conn.read_device_info)
    op("read_state", conn.read_state)
    op("write_control", conn.write_control, pyads.ADSSTATE_RUN, 0, 0, pyads.PLCTYPE_INT)
    op("read", conn.read, 0x4020, 8, pyads.PLCTYPE_INT)
    op("write", conn.write, 0x4020, 8, 1234, pyads.PLCTYPE_INT)
    op("read_write", conn.read_write, 0x4020, 16, pyads.PLCTYPE_DINT, 7, pyads.PLCTYPE_UDINT)
    op("read_by_name", conn.read_by_name, "MAIN.counter", pyads.PLCTYPE_DINT)
    op("write_by_name", conn.write_by_name, "MAIN.speed", 2.5, pyads.PLCTYPE_LREAL)
    op("read_list_by_name", conn.read_list_by_name, ["MAIN.counter", "MAIN.speed", "MAIN.flag"])
    op("write_list_by_name", conn.write_list_by_name, {"MAIN.counter": 3, "MAIN.flag": True})
    received: queue.Queue[tuple[Any, ...]] = queue.Queue()

    def notified(plc_type: Any) -> Any:
        return lambda notification, _name: received.put(conn.parse_notification(notification, plc_type))

    rec.label = "add_device_notification"
    attrib = pyads.NotificationAttrib(4, trans_mode=pyads.ADSTRANS_SERVERONCHA, max_delay=0, cycle_time=0)
    handles = conn.add_device_notification("MAIN.counter", attrib, notified(pyads.PLCTYPE_DINT))
    _, stamp, value = received.get(timeout=2)
    _check_notification(value, NOTIFIED_DINT, stamp)
    rec.label = "del_device_notification"
    conn.del_device_notification(*handles)
    rec.label = "add_device_notification_cyclic"
    attrib = pyads.NotificationAttrib(8, trans_mode=pyads.ADSTRANS_SERVERCYCLE, max_delay=0.0, cycle_time=0.1)
    handles = conn.add_device_notification((0x4040, 0x1008), attrib, notified(pyads.PLCTYPE_LREAL))
    _, stamp, value = received.get(timeout=2)
    _check_notification(value, NOTIFIED_LREAL, stamp)
    conn.del_device_notification(*handles)
    conn.close()
    return pyads.__version__


_NODE_SCRIPT = r"""
const { Client } = require('ads-client');
const [port, op, local] = [Number(process.argv[2]), process.argv[3], process.argv[4]];
const settings = { targetAmsNetId: '127.0.0.1.1.1', targetAdsPort: 851, routerAddress: '127.0.0.1',
  routerTcpPort: port, rawClient: true, autoReconnect: false, timeoutDelay: 2000, hideConsoleWarnings: true };
if (op === 'fullConnect') { settings.rawClient = false; }
if (local === 'local') { settings.localAmsNetId = '192.168.1.60.1.1'; settings.localAdsPort = 32750; }
const c = new Client(settings);
const ops = {
  readRaw: () => c.readRaw(0x4020, 0, 4),
  writeRaw: () => c.writeRaw(0x4020, 4, Buffer.from([1, 2, 3, 4])),
  readWriteRaw: () => c.readWriteRaw(0x4040, 8, 4, Buffer.from([5, 6, 7, 8])),
  readRawMulti: () => c.readRawMulti([{ indexGroup: 0x4020, indexOffset: 0, size: 4 },
                                      { indexGroup: 0x4040, indexOffset: 0x1008, size: 8 }]),
  writeRawMulti: () => c.writeRawMulti([{ indexGroup: 0x4020, indexOffset: 0, value: Buffer.from([1, 0]) },
                                        { indexGroup: 0x4020, indexOffset: 2, value: Buffer.from([9]) }]),
  readWriteRawMulti: () => c.readWriteRawMulti([{ indexGroup: 0x4040, indexOffset: 1, size: 2,
                                                  value: Buffer.from([1, 2, 3]) }]),
  subscribeRaw: async () => {
    let got;
    const first = new Promise((resolve) => { got = resolve; });
    const s = await c.subscribeRaw(0x4020, 0, 4, (data) => got(data), 100, true);
    const data = await Promise.race([first, new Promise((_, no) => setTimeout(() => no('no sample'), 2000))]);
    const value = data.value.readInt32LE(0);
    console.log(JSON.stringify({ value, timestamp: data.timestamp.toISOString() }));
    await s.unsubscribe(); },
  readDeviceInfo: () => c.readDeviceInfo(),
  readState: () => c.readState(),
  writeControl: () => c.writeControl(5, 0),
  createVariableHandle: async () => { const h = await c.createVariableHandle('MAIN.counter');
                                      await c.readRawByHandle(h, 4); await c.deleteVariableHandle(h); },
  getSymbol: () => c.getSymbol('MAIN.counter'),
  readPlcUploadInfo: () => c.readPlcUploadInfo(),
  readPlcSymbolVersion: () => c.readPlcSymbolVersion(),
  fullConnect: () => new Promise((resolve) => setTimeout(resolve, 300)),  // let the first samples arrive
};
(async () => {
  await c.connect();
  await ops[op]();
  await c.disconnect();
})().then(() => process.exit(0), (e) => { console.error(op, e); process.exit(1); });
"""

_NODE_OPS = [
    "readRaw",
    "writeRaw",
    "readWriteRaw",
    "readRawMulti",
    "writeRawMulti",
    "readWriteRawMulti",
    "subscribeRaw",
    "readDeviceInfo",
    "readState",
    "writeControl",
    "createVariableHandle",
    "getSymbol",
    "readPlcUploadInfo",
    "readPlcSymbolVersion",
    "fullConnect",
]


def record_node(rec: Recorder, node_dir: Path) -> str:
    script = node_dir / "ads_record_ops.js"
    script.write_text(_NODE_SCRIPT)
    version = json.loads((node_dir / "node_modules/ads-client/package.json").read_text())["version"]
    runs = [(op, "local") for op in _NODE_OPS] + [("readState", "router")]
    for op, local in runs:
        rec.label = op if local == "local" else f"{op} (no local NetId: port connect first)"
        if op == "fullConnect":
            rec.label = "connect (rawClient: false): system state, ADS state and symbol version watches"
        done = subprocess.run(
            ["node", str(script), str(rec.port), op, local],
            cwd=node_dir,
            check=True,
            timeout=30,
            capture_output=True,
            text=True,
        )
        if op == "subscribeRaw":
            sample = json.loads(done.stdout.strip().splitlines()[-1])
            stamp = datetime.fromisoformat(sample["timestamp"].replace("Z", "+00:00"))
            _check_notification(sample["value"], NOTIFIED_DINT, stamp)
        time.sleep(0.1)  # a port close may trail the process exit
    return version


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--node-dir", type=Path, required=True, help="where `npm install ads-client@2` ran")
    parser.add_argument("--out", type=Path, default=Path("tests/data/ads_golden_frames.json"))
    args = parser.parse_args()

    pyads_rec = Recorder()
    pyads_version = record_pyads(pyads_rec)
    node_rec = Recorder()
    node_version = record_node(node_rec, args.node_dir)
    result = {
        "note": (
            "Frames recorded by tests/tools/ads_record.py. client->server: the exact bytes the client "
            "sent. server->client: the recorder's hand-built reply, which the client accepted (it went on "
            "to its next request without an error)."
        ),
        "sessions": [
            {
                "client": f"pyads {pyads_version} (bundled Beckhoff AdsLib), Python {sys.version.split()[0]}",
                "frames": pyads_rec.frames,
            },
            {"client": f"Node ads-client {node_version} (rawClient: true)", "frames": node_rec.frames},
        ],
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"{len(pyads_rec.frames)} pyads and {len(node_rec.frames)} ads-client frames -> {args.out}")


if __name__ == "__main__":
    main()
