#!/usr/bin/env bash
# Stand-ins for the public base images of the bench, built from Debian's packages (issue 23).
#
#   docker/stand-in-images.sh            make python:3.11-slim and eclipse-mosquitto:2 available
#   docker/stand-in-images.sh --force    rebuild the stand-ins even where the images are present
#
# The Dockerfile starts FROM python:3.11-slim and docker-compose.yml runs eclipse-mosquitto:2. Where an
# image registry is reachable, docker pulls them and this script is not needed. Where none is (CI
# machines that reach Debian's mirror and PyPI but no registry), this script gives docker the two names
# so that the project's own files build unmodified:
#
#   * an image present already (pulled, or a stand-in made before) is kept; else a pull is tried;
#   * else one minimal Debian bookworm (debootstrap --variant=minbase) with python3 (3.11, pip and the
#     headers, as python:3.11-slim has them), mosquitto and mosquitto-clients, imported with
#     `docker import` as python:3.11-slim, and the same with mosquitto's command as eclipse-mosquitto:2.
#
# What a stand-in differs in: Debian's python3 (/usr/bin, 3.11.2) instead of python.org's (/usr/local);
# Debian's mosquitto 2.0 instead of the Alpine build. Both carry the label org.hli-server.stand-in.
# A build inside a container does not see the host's trust store or pip settings, so a stand-in gets
# the host's CA bundle (/etc/ssl/certs/ca-certificates.crt), its system-wide pip configuration
# (/etc/pip.conf, /etc/xdg/pip/, with the files they name) and the PIP_* index variables of this
# environment: a pip or apt behind a TLS-inspecting proxy then works in the build as on the host.
#
# Needs: root, a running Docker engine, debootstrap; network access to the Debian mirror
# (HLI_DEBIAN_MIRROR, default http://deb.debian.org/debian). About 2 minutes and 250 MB.
set -euo pipefail

PYTHON_TAG=python:3.11-slim
MOSQUITTO_TAG=eclipse-mosquitto:2
SUITE=bookworm
MIRROR=${HLI_DEBIAN_MIRROR:-http://deb.debian.org/debian}
LABEL=org.hli-server.stand-in
PACKAGES=python3,python3-pip,python-is-python3,libpython3.11-dev,ca-certificates,mosquitto,mosquitto-clients

force=0
case "${1:-}" in
    --force) force=1 ;;
    "") ;;
    *) echo "usage: $0 [--force]" >&2; exit 2 ;;
esac

docker info >/dev/null 2>&1 || { echo "stand-in-images: no Docker engine answers (docker info)" >&2; exit 1; }

present() { docker image inspect "$1" >/dev/null 2>&1; }

missing=()
for tag in "$PYTHON_TAG" "$MOSQUITTO_TAG"; do
    if [ "$force" = 1 ]; then
        missing+=("$tag")
    elif present "$tag"; then
        how=$(docker image inspect --format "{{index .Config.Labels \"$LABEL\"}}" "$tag" 2>/dev/null || true)
        echo "stand-in-images: $tag is present${how:+ (stand-in: $how)}"
    elif timeout 60 docker pull --quiet "$tag" >/dev/null 2>&1; then
        echo "stand-in-images: $tag pulled"
    else
        missing+=("$tag")
    fi
done
[ "${#missing[@]}" -eq 0 ] && exit 0

[ "$(id -u)" = 0 ] || { echo "stand-in-images: debootstrap needs root" >&2; exit 1; }
command -v debootstrap >/dev/null 2>&1 || [ -x /usr/sbin/debootstrap ] \
    || { echo "stand-in-images: debootstrap is missing (apt-get install debootstrap)" >&2; exit 1; }

work=$(mktemp -d /tmp/hli-stand-in.XXXXXX)
trap 'rm -rf "$work"' EXIT
root=$work/rootfs
echo "stand-in-images: debootstrap $SUITE from $MIRROR (for: ${missing[*]})"
PATH=$PATH:/usr/sbin:/sbin debootstrap --variant=minbase --include="$PACKAGES" "$SUITE" "$root" "$MIRROR" \
    >"$work/debootstrap.log" 2>&1 || { tail -20 "$work/debootstrap.log" >&2; exit 1; }

# what the public images have and a Debian system lacks or forbids
rm -f "$root"/usr/lib/python3*/EXTERNALLY-MANAGED           # pip installs freely, as in python:3.11-slim
mkdir -p "$root/mosquitto/config" "$root/mosquitto/data" "$root/mosquitto/log"
chroot "$root" chown mosquitto: /mosquitto/data /mosquitto/log
# the host's trust store and pip settings (see the header)
cp /etc/ssl/certs/ca-certificates.crt "$root/etc/ssl/certs/ca-certificates.crt"
for conf in /etc/pip.conf /etc/xdg/pip; do
    [ -e "$conf" ] || continue
    mkdir -p "$root$(dirname "$conf")"
    cp -a "$conf" "$root$conf"
done
# the files these configurations name (a constraints file, a certificate) come along
grep -rhoE '^[[:space:]]*(constraint|requirement|cert|client-cert)[[:space:]]*=[[:space:]]*/[^[:space:]]+' \
        /etc/pip.conf /etc/xdg/pip 2>/dev/null | sed -E 's/.*=[[:space:]]*//' | sort -u | while read -r file; do
    [ -f "$file" ] && mkdir -p "$root$(dirname "$file")" && cp "$file" "$root$file"
done
chroot "$root" apt-get clean
rm -rf "$root"/var/lib/apt/lists/* "$root"/var/cache/apt/*.bin "$root"/tmp/* "$root"/root/.cache

changes=(--change "ENV LANG=C.UTF-8" --change "LABEL $LABEL=debian-$SUITE")
for var in PIP_INDEX_URL PIP_EXTRA_INDEX_URL PIP_TRUSTED_HOST PIP_DEFAULT_TIMEOUT; do
    value=${!var:-}
    # an index on this machine's disk (file://) is not inside the container: leave it out
    [ -n "$value" ] && [[ "$value" != *file:* ]] && changes+=(--change "ENV $var=$value")
done

BASE=hli-stand-in:$SUITE
echo "stand-in-images: importing $BASE"
tar -C "$root" -c . | docker import "${changes[@]}" --change 'CMD ["python3"]' - "$BASE" >/dev/null
for tag in "${missing[@]}"; do
    if [ "$tag" = "$PYTHON_TAG" ]; then
        docker tag "$BASE" "$PYTHON_TAG"
    else  # the broker: the same system with mosquitto's command and port, as the public image runs it
        printf '%s\n' "FROM $BASE" "EXPOSE 1883" \
            'CMD ["/usr/sbin/mosquitto", "-c", "/mosquitto/config/mosquitto.conf"]' \
            | docker build --quiet --tag "$MOSQUITTO_TAG" - >/dev/null
    fi
    echo "stand-in-images: $tag is a stand-in built from Debian $SUITE"
done
