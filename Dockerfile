# hli-server: one simulated CNC per container (H-09). docker-compose.yml runs a test farm of them with
# an MQTT broker and a demo PLC; the same image runs under any orchestrator (docs/docker.md).
#
#   docker build -t hli-server .
#   docker run --rm -p 127.0.0.1:8080:8080 -p 127.0.0.1:5020:5020 -p 127.0.0.1:48898:48898 hli-server
#
# Two stages: the first compiles the engine with mypyc (setup.py; a C compiler is needed only there)
# and builds the wheels of the package and its dependencies; the second installs them, nothing else.

FROM python:3.11-slim AS build
RUN apt-get update \
    && apt-get install -y --no-install-recommends gcc libc6-dev \
    && rm -rf /var/lib/apt/lists/*
WORKDIR /src
COPY pyproject.toml setup.py README.md ./
COPY schemas ./schemas
COPY hli_server ./hli_server
COPY plc_clients ./plc_clients
# (the engine build cache of setup.py is of no use in a throw-away stage: off)
RUN HLI_BUILD_CACHE=off pip wheel --no-cache-dir --wheel-dir /wheels .

FROM python:3.11-slim
ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1
COPY --from=build /wheels /wheels
# the build must have compiled the engine (else the image would run it 2-4x slower without saying so)
RUN pip install --no-cache-dir --no-index --find-links /wheels hli-server \
    && rm -rf /wheels \
    && python -c "import sys, hli_server._compiled as c; sys.exit(0 if c.ENGINE_COMPILED else 'engine not compiled')" \
    && useradd --system --uid 10001 --no-create-home hli
USER hli
WORKDIR /tmp

# HTTP control API, Modbus TCP, ADS (AMS/TCP)
EXPOSE 8080 5020 48898

# healthy = ready: every door the command asked for listens (GET /api/ready answers 200, else 503)
HEALTHCHECK --interval=10s --timeout=5s --start-period=20s --retries=3 \
    CMD ["python", "-c", "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8080/api/ready', timeout=3)"]

# Inside a container the doors listen on every interface, without an API token (--insecure): publish
# them on the host's loopback only (docker run -p 127.0.0.1:8080:8080 ...), as docker-compose.yml does,
# or give -e HLI_API_TOKEN=... so that only holders of the token change the machine (docs/docker.md).
# Connections published by docker arrive from its bridge network: ADS admits the private networks.
# --insecure warns that HTTP and Modbus take writes from anyone who reaches them (docs/docker.md).
CMD ["hli-server", "run", "--bind", "0.0.0.0", "--insecure", "--http-port", "8080", "--modbus-port", "5020", \
     "--ads-port", "48898", "--adapter", "ads:allow=loopback;10.0.0.0/8;172.16.0.0/12;192.168.0.0/16"]
