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

installed() {
    [ "$(dpkg-query -W -f='${Status}' "$1" 2>/dev/null || true)" = "install ok installed" ]
}

# A line a|b|...: any one of them (the first this system's archive has, when none is).
missing=()
while read -r line; do
    [ -z "$line" ] && continue
    IFS='|' read -ra alternatives <<< "$line"
    found=0
    for pkg in "${alternatives[@]}"; do
        installed "$pkg" && { found=1; break; }
    done
    [ "$found" = 1 ] || missing+=("$line")
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

export DEBIAN_FRONTEND=noninteractive
"${sudo[@]}" apt-get update -qq
chosen=()
for line in "${missing[@]}"; do
    IFS='|' read -ra alternatives <<< "$line"
    pick="${alternatives[0]}"
    for pkg in "${alternatives[@]}"; do
        if apt-cache show "$pkg" >/dev/null 2>&1; then pick="$pkg"; break; fi
    done
    chosen+=("$pick")
done
echo "optrack: installing system packages: ${chosen[*]}" >&2
"${sudo[@]}" apt-get install -y -qq --no-install-recommends "${chosen[@]}" >/dev/null
