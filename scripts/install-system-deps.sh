#!/usr/bin/env bash
# Installs the system packages the project needs, with apt-get as root:
# - libusb-1.0-0 (open3d needs it): required, the script fails without it;
# - chromium and chromium-driver (the web view's browser tests): optional, the script warns
#   and goes on without them (those tests are then skipped, saying why).
set -euo pipefail

missing_libusb() { ! ldconfig -p 2>/dev/null | grep 'libusb-1.0.so.0' >/dev/null; }
missing_chromium() { ! command -v chromium >/dev/null 2>&1 || ! command -v chromedriver >/dev/null 2>&1; }

can_apt() { [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; }

packages=()
missing_libusb && packages+=(libusb-1.0-0)
missing_chromium && packages+=(chromium chromium-driver)
[ ${#packages[@]} -eq 0 ] && exit 0

if can_apt; then
    echo "installing ${packages[*]}" >&2
    apt-get update -qq || echo "warning: apt-get update failed; trying the cached lists" >&2
    export DEBIAN_FRONTEND=noninteractive
    if missing_libusb; then
        apt-get install -y -qq --no-install-recommends libusb-1.0-0 >/dev/null
    fi
    if missing_chromium; then
        apt-get install -y -qq --no-install-recommends chromium chromium-driver >/dev/null \
            || echo "warning: could not install chromium and chromium-driver;" \
                "the browser tests of the web view will be skipped" >&2
    fi
fi

if missing_libusb; then
    echo "error: open3d needs the system library libusb-1.0." >&2
    echo "install it as root, e.g.: sudo apt-get install -y libusb-1.0-0" >&2
    exit 1
fi
if missing_chromium; then
    echo "note: chromium and chromium-driver are not installed: the browser tests of the web" >&2
    echo "view will be skipped. Install them as root: sudo apt-get install -y chromium chromium-driver" >&2
fi
exit 0
