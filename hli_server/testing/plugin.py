"""The pytest plugin of hli-server (H-07): an in-process server per test, stepped, on free ports.

Registered by the ``pytest11`` entry point of the package, so a user who installed ``hli-server``
writes a test file and nothing else (docs/testing.md)::

    def test_the_limit_holds_x(hli, plc_transport):
        ...

Fixtures:

* ``hli``: a started :class:`~hli_server.testing.Harness` (the server with the stepped clock; stopped
  after the test). Which machine: the ``hli`` marker's ``machine=``, else the ``hli_machine``
  fixture (override or parametrize it), else the ``hli_machine`` ini option, else the demo machine.
  ``@pytest.mark.hli(image="shm")`` puts the image into ``/dev/shm`` (default: a buffer of this
  process); ``adapters=["http"]`` opens doors at start (``hli.serve(...)`` opens them later).
* ``plc_transport``: a synchronous ``plc_clients`` transport to ``hli``'s server, the test runs once
  per door: ``shm``, ``modbus``, ``ads`` (:mod:`hli_server.testing.transports`; a door whose parts
  are not installed is skipped with the reason). Narrow it with
  ``@pytest.mark.parametrize("plc_transport", ["shm"], indirect=True)``.
* ``hli_machine``: the machine of ``hli`` (see above).
* ``hli_url``: the remote CNC this process drives (``--hli-url``), or None.

Nothing is shared between tests or between pytest-xdist workers: every ``hli`` has its own image
(named after the worker's pid) and its own free ports, so a suite runs under ``-n auto`` unchanged.

**A fleet of CNCs** (``--hli-url``): ``hli`` is then a :class:`~hli_server.testing.remote.RemoteHarness`
that drives a server running elsewhere (``hli-server run --clock stepped``: a container, a pod of
deploy/kubernetes) over its HTTP API, restarted at the start of every test; under pytest-xdist each worker
takes one CNC of the list (``--hli-url`` once per CNC, ``@FILE`` with one per line, or a pattern with
``{n}``, the worker's number). docs/testing.md, "A fleet of CNCs", says what differs.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from hli_server.testing.harness import Harness
    from plc_clients.transports import Transport

__all__ = ["hli", "hli_machine", "plc_transport"]

_MARKER = (
    "hli(machine=None, image='memory', adapters=(), program_dirs=None, nc_output_dir=None): options of "
    "the `hli` fixture (hli-server's pytest plugin, H-07): the machine file or configuration, 'memory' or "
    "'shm' for the process image, doors to open at start, where `L name` finds subprograms (relative to "
    "the test file), where #MSG SAVE writes"
)
_IMAGE_KINDS = ("memory", "shm")


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("hli-server", "hli-server's pytest plugin (docs/testing.md)")
    group.addoption(
        "--hli-url",
        action="append",
        default=[],
        metavar="URL",
        help="drive the hli-server at URL (its HTTP API; it runs --clock stepped) instead of one in-process: "
        "repeat it once per CNC, or @FILE (one URL a line), or a pattern with {n}; each pytest-xdist "
        "worker takes one CNC (gwN the N-th)",
    )
    group.addoption(
        "--hli-token",
        default=None,
        metavar="TOKEN",
        help="the API token of the --hli-url servers (default: the environment variable HLI_API_TOKEN)",
    )
    parser.addini(
        "hli_machine",
        "machine file of the `hli` fixture (hli-server), relative to the rootdir; default: the demo machine",
        default="",
    )
    parser.addini(
        "hli_program_dirs",
        "program directories of the `hli` fixture (hli-server): where `L name` finds subprograms, relative "
        "to the rootdir, one per line",
        type="linelist",
        default=[],
    )
    parser.addini(
        "hli_image",
        "process image of the `hli` fixture: memory (default) or shm (/dev/shm)",
        default="memory",
    )


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", _MARKER)


def _urls(config: pytest.Config) -> list[str]:
    urls: list[str] = []
    for value in config.getoption("hli_url", default=None) or []:
        if value.startswith("@"):
            lines = Path(value[1:]).read_text(encoding="utf-8").splitlines()
            urls.extend(line.strip() for line in lines if line.strip() and not line.lstrip().startswith("#"))
        else:
            urls.append(value)
    return urls


def pytest_report_header(config: pytest.Config) -> str | None:
    urls = _urls(config)
    if not urls:
        return None
    shown = ", ".join(urls[:3]) + (f" and {len(urls) - 3} more" if len(urls) > 3 else "")
    return f"hli-server: remote CNCs (--hli-url): {shown}"


@pytest.fixture(scope="session")
def hli_url(pytestconfig: pytest.Config) -> str | None:
    """The remote CNC this process drives (``--hli-url``; under pytest-xdist the worker's own), or None
    where ``hli`` runs the server in-process."""
    urls = _urls(pytestconfig)
    if not urls:
        return None
    from hli_server.testing.remote import worker_url

    try:
        return worker_url(urls, _worker_id(pytestconfig))
    except ValueError as exc:
        raise pytest.UsageError(str(exc)) from None


def _worker_id(config: pytest.Config) -> str | None:
    """This process' pytest-xdist worker ("gw0", ...), None in a run without workers: from xdist's own
    ``workerinput``, not the environment (a pytest started inside a worker's test inherits its
    ``PYTEST_XDIST_WORKER`` without being a worker)."""
    workerinput = getattr(config, "workerinput", None)
    return str(workerinput["workerid"]) if isinstance(workerinput, dict) else None


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    """Run a test that takes ``plc_transport`` once per registered door, unless it chose its own."""
    if "plc_transport" not in metafunc.fixturenames:
        return
    for marker in metafunc.definition.iter_markers("parametrize"):
        names = marker.args[0] if marker.args else marker.kwargs.get("argnames", "")
        if isinstance(names, str):
            names = [n.strip() for n in names.split(",")]
        if "plc_transport" in names:
            return
    from hli_server.testing.transports import transport_names

    metafunc.parametrize("plc_transport", transport_names(), indirect=True)


def _hli_marker(request: pytest.FixtureRequest) -> dict[str, Any]:
    marker = request.node.get_closest_marker("hli")
    if marker is None:
        return {}
    if marker.args:
        raise pytest.UsageError(
            f"{request.node.nodeid}: write @pytest.mark.hli(machine=..., image=..., adapters=...) with names"
        )
    known = {"machine", "image", "adapters", "program_dirs", "nc_output_dir"}
    unknown = set(marker.kwargs) - known
    if unknown:
        raise pytest.UsageError(
            f"{request.node.nodeid}: @pytest.mark.hli takes {', '.join(sorted(known))}, "
            f"not {', '.join(sorted(unknown))}"
        )
    return dict(marker.kwargs)


@pytest.fixture
def hli_machine(request: pytest.FixtureRequest) -> Any:
    """The machine of the ``hli`` fixture: a machine file (relative to the test file), a
    ``MachineConfig``, or None for the demo machine. Override or parametrize it to choose per test."""
    options = _hli_marker(request)
    if options.get("machine") is not None:
        return options["machine"]
    configured = str(request.config.getini("hli_machine") or "")
    if configured:
        return request.config.rootpath / configured
    return None


@pytest.fixture
def hli(request: pytest.FixtureRequest, hli_machine: Any, hli_url: str | None) -> Iterator[Harness]:
    """An in-process hli-server with the stepped clock, started for this test and stopped after it; with
    ``--hli-url`` the remote CNC of this worker, its machine restarted for this test."""
    from hli_server.testing.harness import Harness

    options = _hli_marker(request)
    image = str(options.get("image") or request.config.getini("hli_image") or "memory")
    if image not in _IMAGE_KINDS:
        raise pytest.UsageError(f"hli image {image!r}: use one of {', '.join(_IMAGE_KINDS)}")
    base = Path(request.path).parent if request.path is not None else None
    dirs = options.get("program_dirs")
    if dirs is None:
        dirs = [request.config.rootpath / d for d in request.config.getini("hli_program_dirs")]
    elif isinstance(dirs, str | os.PathLike):
        dirs = [dirs]
    if hli_url is not None:
        yield from _remote(request, hli_url, hli_machine, base, dirs, options)
        return
    harness = Harness(
        hli_machine,
        image=image,  # type: ignore[arg-type]
        adapters=options.get("adapters", ()),
        base=base,
        program_dirs=dirs,
        nc_output_dir=options.get("nc_output_dir"),
    )
    with harness:
        yield harness


def _remote(
    request: pytest.FixtureRequest,
    url: str,
    machine: Any,
    base: Path | None,
    dirs: Any,
    options: dict[str, Any],
) -> Iterator[Any]:
    """``hli`` of a remote CNC: a test for another machine than the CNC's, or for a door it does not
    serve, is skipped, saying why."""
    from hli_server.testing.harness import load_machine_spec
    from hli_server.testing.remote import RemoteHarness

    token = request.config.getoption("hli_token", default=None) or os.environ.get("HLI_API_TOKEN") or None
    harness = RemoteHarness(url, token=token, machine=machine, base=base, program_dirs=dirs or ())
    with harness:
        expected = load_machine_spec(machine, base).name
        if harness.machine["name"] != expected:
            pytest.skip(
                f"the test is for machine {expected!r}; the CNC at {url} runs {harness.machine['name']!r}"
            )
        for spec in options.get("adapters", ()):
            name = spec if isinstance(spec, str) else spec[0]
            if name not in harness.ports:
                pytest.skip(f"the test wants the {name} door; the CNC at {url} does not serve it")
        yield harness


@pytest.fixture
def plc_transport(request: pytest.FixtureRequest, hli: Harness) -> Iterator[Transport]:
    """A synchronous PLC transport to ``hli``'s server, once per door (shm, modbus, ads)."""
    from hli_server.testing.transports import open_transport, unavailable

    name = getattr(request, "param", "shm")
    reason = unavailable(name)
    if reason is None and getattr(hli, "remote", False):
        if name == "shm":
            reason = f"the shm door: the CNC at {hli.http_url} is remote, its image is not in this memory"
        elif name not in getattr(hli, "ports", {}):
            reason = f"the {name} door: the CNC at {hli.http_url} does not serve it"
    if reason is not None:
        pytest.skip(reason)
    transport = open_transport(hli, name)
    try:
        yield transport
    finally:
        transport.close()
