# hli-server: one simulated CNC per container (H-09). docker-compose.yml runs a test farm of them with
# an MQTT broker and a demo PLC; the same image runs under any orchestrator (docs/docker.md).
#
#   docker build -t hli-server .
#   docker run --rm -p 127.0.0.1:8080:8080 -p 127.0.0.1:5020:5020 hli-server
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1

WORKDIR /app
COPY pyproject.toml README.md ./
COPY schemas ./schemas
COPY hli_server ./hli_server
COPY plc_clients ./plc_clients
RUN pip install --no-cache-dir . \
    && useradd --system --uid 10001 --no-create-home hli
USER hli

# HTTP control API, Modbus TCP, ADS (AMS/TCP)
EXPOSE 8080 5020 48898

# healthy = the HTTP control API answers (the clock runs inside the same event loop)
HEALTHCHECK --interval=10s --timeout=5s --start-period=20s --retries=3 \
    CMD ["python", "-c", "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8080/api/timing', timeout=3)"]

# inside a container the doors listen on every interface; publish them on the host's loopback only
# (docker run -p 127.0.0.1:8080:8080 ...), as docker-compose.yml does; --insecure says so (it warns that
# HTTP and Modbus take writes from anyone who reaches them: docs/docker.md, "Under any orchestrator")
CMD ["hli-server", "run", "--bind", "0.0.0.0", "--insecure", "--http-port", "8080", "--modbus-port", "5020"]
