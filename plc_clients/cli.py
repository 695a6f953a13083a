"""``hli-plc``: run a demo PLC program against a running hli-server, over any transport (H-06).

::

    hli-plc c43-obstacle --transport shm --image hli_demo
    hli-plc c14-manual --transport modbus --host 127.0.0.1 --port 5020 --http http://127.0.0.1:8080
    hli-plc c3-collision --transport ads --host 127.0.0.1 --port 48898
    hli-plc c43-obstacle --transport modbus --host cnc1 --http http://cnc1:8080 --repeat   # a bench's PLC
    hli-plc --list

The demos are :mod:`plc_clients.demos` (the examples of FCT-C43, FCT-C14, FCT-C3 and V.E.). First the PLC's
door is opened (the transport connects, the layout is read): a PLC that cannot reach the CNC changes
nothing. Then the operator's part: the demo's NC program is loaded into its channel through the
server's HTTP API (``--http``; the channel is reset first; ``--no-load`` skips it). Then the PLC
program runs in a :class:`~plc_clients.task.PlcTask` paced to ``--cycle-ms`` until the demo is over,
printing what it does with the CNC cycle of each step. The Modbus and ADS transports take the layout
from ``--layout`` (a file of ``hli-server map --format json``) or from the HTTP API. ``--repeat`` runs
the demo again and again (``--pause`` seconds apart) until stopped: the PLC of the compose bench.

Exit codes: 0 the demo ran to its end (or, with ``--repeat``, SIGTERM stopped it), 1 the demo failed
(the CNC raised an error it should not have, a block reported an error), 2 usage or connection errors
(no server, wrong image name), 130 Ctrl+C. SIGTERM stops it like Ctrl+C (also as a container's first
process, which ignores an unhandled SIGTERM).
"""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import os
import signal
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Sequence
from typing import Any

from plc_clients.demos import DEMOS, Demo, demo_class
from plc_clients.task import PlcTask
from plc_clients.transports import ModbusTransport, ShmTransport, Transport, TransportError, load_layout
from schemas.layout import LayoutError

__all__ = ["main"]

TRANSPORT_NAMES = ("shm", "modbus", "ads")
DEFAULT_PORTS = {"modbus": 5020, "ads": 48898}


class UsageError(Exception):
    """Something the user must fix: a missing option, no server where they said."""


class _Terminated(BaseException):  # like KeyboardInterrupt: no `except Exception` swallows it
    """SIGTERM: stop as after Ctrl+C, exit 0."""


def _on_sigterm(signum: int, frame: object) -> None:
    raise _Terminated


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="hli-plc",
        description="Run a demo PLC program (the examples of FCT-C43, FCT-C14, FCT-C3 and V.E. variables) "
        "against a running hli-server, printing what it does.",
        epilog="demos: " + ", ".join(DEMOS),
    )
    ap.add_argument("demo", nargs="?", choices=DEMOS, help="the demo to run")
    ap.add_argument("--list", action="store_true", help="list the demos and exit")
    ap.add_argument(
        "--transport", choices=TRANSPORT_NAMES, default="shm", help="the PLC's door (default shm)"
    )
    ap.add_argument("--image", help="shm: the image name `hli-server run` prints (--image-name)")
    ap.add_argument("--host", default="127.0.0.1", help="modbus/ads: the server's address")
    ap.add_argument("--port", type=int, help="modbus/ads: the port (default 5020 / 48898)")
    ap.add_argument("--word-order", default="ABCD", choices=("ABCD", "CDAB"), help="modbus: the server's")
    ap.add_argument("--unit-id", type=int, default=1, help="modbus: the server's unit id")
    ap.add_argument(
        "--http",
        default="http://127.0.0.1:8080",
        help="the server's HTTP API: loads the demo's NC program (the operator's part) and gives the layout",
    )
    ap.add_argument(
        "--layout", help="modbus/ads: a layout file (`hli-server map --format json`); default: --http"
    )
    ap.add_argument(
        "--no-load", action="store_true", help="do not load the NC program (it is loaded already)"
    )
    ap.add_argument("--cycle-ms", type=float, default=10.0, help="the PLC task's cycle (default 10 ms)")
    ap.add_argument(
        "--timeout", type=float, default=120.0, help="give up a run after this many seconds (default 120)"
    )
    ap.add_argument(
        "--repeat",
        action="store_true",
        help="run the demo again and again until stopped (SIGTERM, Ctrl+C); a failed run is reported "
        "and the next one starts",
    )
    ap.add_argument("--pause", type=float, default=2.0, help="--repeat: seconds between runs (default 2)")
    ap.add_argument(
        "--wait", type=float, default=5.0, help="shm: wait this long for the server's image (default 5 s)"
    )
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.list or args.demo is None:
        for name in DEMOS:
            cls = demo_class(name)
            print(f"{name:14} {cls.document:8} channel {cls.channel}: {cls.summary}")
        return 0 if args.list else 2
    logging.basicConfig(level=logging.WARNING, format="hli-plc: %(message)s")  # the task's overruns
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        return _run(args)
    except (UsageError, TransportError, LayoutError, FileNotFoundError) as exc:
        print(f"hli-plc: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("hli-plc: interrupted", file=sys.stderr)
        return 130
    except _Terminated:
        print("hli-plc: stopped (SIGTERM)", file=sys.stderr)
        return 0
    finally:
        signal.signal(signal.SIGTERM, previous)


def _run(args: argparse.Namespace) -> int:
    # the PLC's door first: where the transport cannot connect, the machine is left as it is
    transport = _open(args)
    try:
        runs = 0
        while True:
            runs += 1
            outcome = _run_once(args, transport, runs if args.repeat else None)
            if not args.repeat:
                return outcome
            time.sleep(args.pause)
    finally:
        transport.close()


def _run_once(args: argparse.Namespace, transport: Transport, run: int | None) -> int:
    demo = demo_class(args.demo)(printer=lambda line: print(line, flush=True))
    which = f" (run {run})" if run is not None else ""
    print(f"hli-plc: {demo.name} ({demo.document}){which}: {demo.summary}", flush=True)
    if not args.no_load:
        _load_program(args.http, demo)
    print(f"hli-plc: PLC task every {args.cycle_ms:g} ms over {transport!r}", flush=True)
    task = PlcTask(transport, args.cycle_ms / 1000.0, demo, watch=demo.watch, name=f"hli-plc {demo.name}")
    began = time.monotonic()
    try:
        task.run(until=lambda: demo.done, timeout_s=args.timeout)
    except TimeoutError:
        print(
            f"hli-plc: the demo did not end within {args.timeout:g} s (step {demo.step!r})", file=sys.stderr
        )
        return 1
    st = task.stats
    faults = st.input_faults + st.output_faults
    print(
        f"hli-plc: {'FAILED' if demo.failed else 'done'}: {st.cycles} PLC cycles in "
        f"{time.monotonic() - began:.1f} s, {st.overruns} overruns, {faults} faults",
        flush=True,
    )
    return 1 if demo.failed else 0


def _http(url: str, body: dict[str, Any] | None = None) -> dict[str, Any]:
    data = None if body is None else json.dumps(body).encode("utf-8")
    headers = {"Content-Type": "application/json"}
    token = os.environ.get("HLI_API_TOKEN")
    if token:  # a server started with --api-token (deploy/kubernetes): its changes need the token
        headers["Authorization"] = f"Bearer {token}"
    request = urllib.request.Request(url, data=data, method="POST", headers=headers)
    with urllib.request.urlopen(request, timeout=5.0) as response:
        answer: dict[str, Any] = json.loads(response.read() or b"{}")
        return answer


def _load_program(http: str, demo: Demo) -> None:
    """The operator's part: reset the channel, then load the demo's NC program (retried while the
    reset is still being latched)."""
    base = http.rstrip("/") + f"/api/channels/{demo.channel}"
    try:
        _http(base + "/reset")
        deadline = time.monotonic() + 5.0
        while True:
            try:
                _http(base + "/program", {"text": demo.nc_program, "name": demo.name, "files": demo.nc_files})
                break
            except urllib.error.HTTPError as exc:
                if exc.code != 409 or time.monotonic() > deadline:
                    detail = exc.read().decode("utf-8", "replace")
                    raise UsageError(
                        f"loading the NC program into channel {demo.channel}: {detail}"
                    ) from None
                time.sleep(0.05)
    except urllib.error.URLError as exc:
        raise UsageError(
            f"no HTTP API at {http} ({exc.reason}): start `hli-server run`, pass --http, "
            "or --no-load when the program is loaded already"
        ) from None
    print(
        f"hli-plc: operator: NC program of {demo.name} loaded into channel {demo.channel} ({http})",
        flush=True,
    )


def _open(args: argparse.Namespace) -> Transport:
    kind = args.transport
    if kind == "shm":
        if not args.image:
            raise UsageError("--transport shm needs --image NAME (the name `hli-server run` prints)")
        return ShmTransport.attach(args.image, timeout=args.wait)
    port = args.port or DEFAULT_PORTS[kind]
    layout = load_layout(args.layout or args.http)
    if kind == "modbus":
        return ModbusTransport.connect(
            args.host, port, layout=layout, word_order=args.word_order, unit_id=args.unit_id
        )
    try:
        ads = importlib.import_module("plc_clients.ads")
    except ModuleNotFoundError:
        raise UsageError("the ADS transport (plc_clients.ads) is not part of this installation yet") from None
    transport: Transport = ads.AdsTransport.connect(args.host, port, layout=layout)
    return transport


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
