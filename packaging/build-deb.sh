#!/usr/bin/env bash
# Builds dist/optrack_<version>_amd64.deb from the wheel (make wheel) and the pinned
# dependencies, through pip's configured index (and its cache): the application in its
# own Python environment under /opt/optrack, /usr/bin/optrack, the desktop entry and
# icon, the cameras' udev rules, the systemd units for headless computers and the
# default site configuration in /etc/optrack. Depends: the runtime system packages of
# packaging/debian-packages.txt and the Python the environment was made with.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
cd "$repo"
# The distribution's Python (not a pyenv or other private one): the package depends on it.
python="$(readlink -f "${DEB_PYTHON:-/usr/bin/python3}")"   # /usr/bin/python3.11
version="$(sed -n 's/^__version__ = "\(.*\)"$/\1/p' optrack/__init__.py)"
wheel="dist/optrack-$version-py3-none-any.whl"
[ -f "$wheel" ] || { echo "build-deb: $wheel is missing; run make wheel first." >&2; exit 1; }
arch="$(dpkg --print-architecture)"
stage="$repo/build/deb/optrack_${version}_${arch}"
deb="dist/optrack_${version}_${arch}.deb"
rm -rf "$stage"
mkdir -p "$stage/DEBIAN"

# The Python environment, made in the staging tree and then moved to /opt/optrack
# by rewriting the staging path out of its scripts.
"$python" -m venv --without-pip "$stage/opt/optrack"
"$repo/.venv/bin/python" -m pip --python "$stage/opt/optrack/bin/python" install -q --no-compile \
    --disable-pip-version-check "$wheel" 2>&1 | grep -v '^WARNING: Location' >&2 || true
"$stage/opt/optrack/bin/python" -c "import optrack" \
    || { echo "build-deb: the environment could not import optrack" >&2; exit 1; }
grep -rlI --null "$stage" "$stage/opt/optrack/bin" "$stage/opt/optrack/pyvenv.cfg" | xargs -0 -r sed -i "s|$stage||g"
find "$stage/opt/optrack" -name __pycache__ -type d -prune -exec rm -rf {} +
rm -f "$stage/opt/optrack/lib/python"*/site-packages/optrack-*.dist-info/direct_url.json
if grep -rlI "$stage" "$stage/opt/optrack" >/dev/null; then
    echo "build-deb: the staging path is still named in: $(grep -rlI "$stage" "$stage/opt/optrack" | head -3)" >&2
    exit 1
fi

res="optrack/resources"
install -D -m 644 "$res/optrack.desktop" "$stage/usr/share/applications/optrack.desktop"
install -D -m 644 "$res/icons/optrack.svg" "$stage/usr/share/icons/hicolor/scalable/apps/optrack.svg"
install -D -m 644 packaging/udev/99-optrack-cameras.rules "$stage/usr/lib/udev/rules.d/99-optrack-cameras.rules"
install -D -m 644 -t "$stage/usr/lib/systemd/system" packaging/systemd/*.service
install -D -m 644 "$res/config/site.yaml" "$stage/etc/optrack/site.yaml"
install -D -m 644 "$res/config/site.env" "$stage/etc/optrack/site.env"
mkdir -p "$stage/etc/optrack/sensors"
install -D -m 644 "$res/config/sensor.env" "$stage/usr/share/doc/optrack/sensor.env.example"
install -D -m 644 docs/deploy.md "$stage/usr/share/doc/optrack/deploy.md"
mkdir -p "$stage/usr/bin"
ln -s /opt/optrack/bin/optrack "$stage/usr/bin/optrack"

# Depends: the runtime packages (the list's lines above its development-only marker).
runtime="$(sed -e '/^# --- development only/,$d' -e 's/#.*//' -e 's/[[:space:]]//g' \
    packaging/debian-packages.txt | sed '/^$/d' | paste -sd, - | sed 's/,/, /g')"
installed_kb="$(du -sk --exclude=DEBIAN "$stage" | cut -f1)"
cat > "$stage/DEBIAN/control" <<CONTROL
Package: optrack
Version: $version
Architecture: $arch
Maintainer: optrack maintainers <optrack@users.noreply.github.com>
Installed-Size: $installed_kb
Depends: $(basename "$python"), $runtime
Section: science
Priority: optional
Description: people tracking in networks of RGB-D cameras
 An open re-implementation of OpenPTrack operated from one desktop application:
 detector nodes for the cameras, a tracker, UDP/OSC/WebSocket outputs, and
 systemd units (optrack-node@, optrack-tracker) for headless computers.
CONTROL
printf '/etc/optrack/site.yaml\n/etc/optrack/site.env\n' > "$stage/DEBIAN/conffiles"
install -m 755 packaging/debian/postinst packaging/debian/prerm packaging/debian/postrm "$stage/DEBIAN/"
dpkg-deb --root-owner-group -Zzstd --build "$stage" "$deb" >/dev/null
rm -rf "$stage"
echo "$deb"
