"""Test-only helpers: a seeded synthetic run output and a headless-Chromium driver."""
