#!/bin/sh
# Best-effort install of Debian's EGL/Mesa libraries that let VTK (pyvista, the [viz] extra) render
# off screen without a display, and of Chromium, which the tests use to look at hamsa's interactive HTML
# pages the way a person would. Never fails: without them, rendering raises a clear error and the
# browser test is skipped with the reason.
missing=""
if [ ! -e /usr/lib/x86_64-linux-gnu/libEGL_mesa.so.0 ] && [ ! -e /usr/lib/aarch64-linux-gnu/libEGL_mesa.so.0 ]; then
    missing="libegl1 libegl-mesa0 libgl1-mesa-dri"
fi
if ! command -v chromium >/dev/null 2>&1; then
    missing="$missing chromium"
fi
[ -z "$missing" ] && exit 0
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    echo "installing$missing (off-screen rendering, headless browser) ..."
    (apt-get install -y -qq $missing >/dev/null 2>&1 \
        || (apt-get update -qq >/dev/null 2>&1 && apt-get install -y -qq $missing >/dev/null 2>&1)) \
        || echo "notice: could not install$missing; rendering or the browser test will be unavailable"
fi
exit 0
