"""A PLC-side process for the ADS tests: subscribes with pyads and prints what it receives.

    python -m tests.integration._ads_children PORT SYMBOL COUNT

Connects to the server on 127.0.0.1:PORT (AMS NetId 127.0.0.1.1.1, port 851), adds an on-change
device notification on SYMBOL (a DINT), prints ``ready`` and then one JSON line per sample
(``{"handle": ..., "value": ..., "time": ...}``) until COUNT samples arrived, then deletes the
notification, closes and exits 0 (exit 3 when no sample arrived within 10 s). It imports pyads
only, as a separate PLC or HMI process would.
"""

from __future__ import annotations

import json
import queue
import sys

import pyads


def main() -> int:
    port, symbol, count = int(sys.argv[1]), sys.argv[2], int(sys.argv[3])
    pyads.open_port()
    pyads.set_local_address("10.7.7.7.1.1")
    pyads.close_port()
    conn = pyads.Connection("127.0.0.1.1.1", 851, f"127.0.0.1:{port}")
    conn.set_timeout(3000)
    conn.open()
    received: queue.Queue[tuple[int, str, int]] = queue.Queue()

    def callback(notification: object, _name: str) -> None:
        handle, stamp, value = conn.parse_notification(notification, pyads.PLCTYPE_DINT)
        received.put((handle, stamp.isoformat(), value))

    attrib = pyads.NotificationAttrib(4, trans_mode=pyads.ADSTRANS_SERVERONCHA, max_delay=0, cycle_time=0)
    handles = conn.add_device_notification(symbol, attrib, callback)
    print("ready", flush=True)
    for _ in range(count):
        try:
            handle, stamp, value = received.get(timeout=10)
        except queue.Empty:
            return 3
        print(json.dumps({"handle": handle, "value": value, "time": stamp}), flush=True)
    conn.del_device_notification(*handles)
    conn.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
