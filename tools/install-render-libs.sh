#!/bin/sh
# Best-effort install of Debian's EGL/Mesa libraries that let VTK (pyvista, the [viz] extra) render
# off screen without a display. Never fails: without them, rendering raises a clear error.
if [ -e /usr/lib/x86_64-linux-gnu/libEGL_mesa.so.0 ] || [ -e /usr/lib/aarch64-linux-gnu/libEGL_mesa.so.0 ]; then
    exit 0
fi
if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    echo "installing libegl1 libegl-mesa0 libgl1-mesa-dri (off-screen rendering) ..."
    (apt-get install -y -qq libegl1 libegl-mesa0 libgl1-mesa-dri >/dev/null 2>&1 \
        || (apt-get update -qq >/dev/null 2>&1 && apt-get install -y -qq libegl1 libegl-mesa0 libgl1-mesa-dri >/dev/null 2>&1)) \
        || echo "notice: could not install the EGL libraries; rendering will be unavailable"
fi
exit 0
