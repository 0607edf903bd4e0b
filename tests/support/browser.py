"""Headless Debian Chromium for the page tests (the `browser_module` fixture skips without it)."""

CHROMIUM = "/usr/bin/chromium"
