#!/usr/bin/env bash
# Installs the Debian/Ubuntu packages listed in packaging/debian-packages.txt
# that are not installed yet. Quiet and quick when everything is present.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
list="$here/debian-packages.txt"

if ! command -v dpkg-query >/dev/null 2>&1; then
    echo "optrack: this is not a Debian/Ubuntu system; install the packages in $list with your package manager." >&2
    exit 0
fi

missing=()
while read -r pkg; do
    [ -z "$pkg" ] && continue
    status="$(dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null || true)"
    [ "$status" = "install ok installed" ] || missing+=("$pkg")
done < <(sed -e 's/#.*//' -e 's/[[:space:]]//g' "$list")

[ ${#missing[@]} -eq 0 ] && exit 0

if [ "$(id -u)" -eq 0 ]; then
    sudo=()
elif command -v sudo >/dev/null 2>&1; then
    sudo=(sudo)
else
    echo "optrack: missing system packages (${missing[*]}); run this script as root or install sudo." >&2
    exit 1
fi

echo "optrack: installing system packages: ${missing[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
"${sudo[@]}" apt-get update -qq
"${sudo[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
