#!/usr/bin/env bash
# Installs the system library open3d needs (libusb-1.0) when it is missing.
set -euo pipefail
if ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
    exit 0
fi
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing libusb-1.0-0 (needed by open3d)" >&2
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null
else
    echo "error: open3d needs the system library libusb-1.0." >&2
    echo "install it as root, e.g.: sudo apt-get install -y libusb-1.0-0" >&2
    exit 1
fi
