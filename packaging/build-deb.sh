#!/usr/bin/env bash
# Builds dist/optrack_<version>_amd64.deb from the wheel (make wheel) and the pinned
# dependencies, through pip's configured index (and its cache): the application in its
# own Python environment under /opt/optrack, with the Python interpreter it runs on
# (/opt/optrack/python: this distribution's, so the package does not depend on the
# target's own Python version), /usr/bin/optrack, the desktop entry and icon, the
# cameras' udev rules, the systemd units for headless computers and the default site
# configuration in /etc/optrack. Depends: the runtime system packages of
# packaging/debian-packages.txt (the interpreter's libraries among them).
# Each step's seconds go to stderr.
set -euo pipefail
repo="$(cd "$(dirname "$0")/.." && pwd)"
cd "$repo"
# The distribution's Python (not a pyenv or other private one): it is copied in.
python="$(readlink -f "${DEB_PYTHON:-/usr/bin/python3}")"   # /usr/bin/python3.11
pyver="$(basename "$python")"
stdlib="$("$python" -c 'import sysconfig; print(sysconfig.get_path("stdlib"))')"
version="$(sed -n 's/^__version__ = "\(.*\)"$/\1/p' optrack/__init__.py)"
wheel="dist/optrack-$version-py3-none-any.whl"
[ -f "$wheel" ] || { echo "build-deb: $wheel is missing; run make wheel first." >&2; exit 1; }
arch="$(dpkg --print-architecture)"
stage="$repo/build/deb/optrack_${version}_${arch}"
deb="dist/optrack_${version}_${arch}.deb"
SECONDS=0
step() { echo "build-deb: $1 (${SECONDS} s)" >&2; }
rm -rf "$stage"
mkdir -p "$stage/DEBIAN"

# The interpreter and its standard library, less what optrack never runs (tests, IDLE,
# Tk, 2to3, the static library, the modules for dbm, NIS, curses and readline): Python
# finds its library beside its executable, wherever that lies.
base="$stage/opt/optrack/python"
mkdir -p "$base/bin" "$base/lib"
cp "$python" "$base/bin/$pyver"
cp -r "$stdlib" "$base/lib/$pyver"
lib="$base/lib/$pyver"
rm -rf "$lib"/{test,idlelib,tkinter,turtledemo,lib2to3,ensurepip,config-*} "$lib/sitecustomize.py" \
    "$lib"/lib-dynload/{_dbm,_gdbm,nis,_curses,_curses_panel,readline,_crypt,_test,xxlimited,_xxtestfuzz,_ctypes_test}*.so
find "$base" -name __pycache__ -type d -prune -exec rm -rf {} +
step "interpreter"

# The Python environment, made in the staging tree and then moved to /opt/optrack
# by rewriting the staging path out of its scripts and links.
"$base/bin/$pyver" -m venv --without-pip "$stage/opt/optrack"
ln -sfn "../python/bin/$pyver" "$stage/opt/optrack/bin/$pyver"
"$repo/.venv/bin/python" -m pip --python "$stage/opt/optrack/bin/python" install -q --no-compile \
    --disable-pip-version-check "$wheel" 2>&1 | grep -v '^WARNING: Location' >&2 || true
"$stage/opt/optrack/bin/python" -c "import optrack" \
    || { echo "build-deb: the environment could not import optrack" >&2; exit 1; }
step "environment"
grep -rlI --null "$stage" "$stage/opt/optrack/bin" "$stage/opt/optrack/pyvenv.cfg" | xargs -0 -r sed -i "s|$stage||g"
find "$stage/opt/optrack" -name __pycache__ -type d -prune -exec rm -rf {} +
rm -f "$stage/opt/optrack/lib/python"*/site-packages/optrack-*.dist-info/direct_url.json
if grep -rlI "$stage" "$stage/opt/optrack" >/dev/null || find "$stage" -lname "$stage*" | grep -q .; then
    echo "build-deb: the staging path is still named in: $(grep -rlI "$stage" "$stage/opt/optrack" | head -3)" >&2
    exit 1
fi
# The oldest C library everything runs on (Ubuntu 22.04 has 2.35, Debian 12 2.36): the
# interpreter's symbols and the wheels' manylinux_2_NN tags.
glibc="$( { if command -v objdump >/dev/null; then
        find "$base" -type f \( -name "$pyver" -o -name '*.so' \) -exec objdump -T {} + 2>/dev/null \
            | grep -o 'GLIBC_[0-9.]*' | sed 's/GLIBC_//'
    fi
    cat "$stage"/opt/optrack/lib/python*/site-packages/*.dist-info/WHEEL \
        | grep -o 'manylinux_2_[0-9]*' | sed 's/manylinux_2_/2./'
} | sort -Vu | tail -1)"
step "relocated"

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

# Depends: the runtime packages (the list's lines above its development-only marker;
# a|b: either, as Ubuntu 24.04 renamed some libraries, libssl3 -> libssl3t64).
runtime="$(sed -e '/^# --- development only/,$d' -e 's/#.*//' -e 's/[[:space:]]//g' \
    packaging/debian-packages.txt | sed '/^$/d' | paste -sd, - | sed -e 's/,/, /g' -e 's/|/ | /g')"
installed_kb="$(du -sk --exclude=DEBIAN "$stage" | cut -f1)"
cat > "$stage/DEBIAN/control" <<CONTROL
Package: optrack
Version: $version
Architecture: $arch
Maintainer: optrack maintainers <optrack@users.noreply.github.com>
Installed-Size: $installed_kb
Depends: ${glibc:+libc6 (>= $glibc), }$runtime
Section: science
Priority: optional
Description: people tracking in networks of RGB-D cameras
 An open re-implementation of OpenPTrack operated from one desktop application:
 detector nodes for the cameras, a tracker, UDP/OSC/WebSocket outputs, and
 systemd units (optrack-node@, optrack-tracker) for headless computers.
CONTROL
printf '/etc/optrack/site.yaml\n/etc/optrack/site.env\n' > "$stage/DEBIAN/conffiles"
install -m 755 packaging/debian/postinst packaging/debian/prerm packaging/debian/postrm "$stage/DEBIAN/"
# zstd: dpkg reads it on Debian 12 (dpkg >= 1.21.18) and on Ubuntu since 18.04.
dpkg-deb --root-owner-group -Zzstd --build "$stage" "$deb" >/dev/null
step "dpkg-deb"
rm -rf "$stage"
step "done"
echo "$deb"
