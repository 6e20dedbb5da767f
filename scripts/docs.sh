#!/usr/bin/env bash
# Build the documentation site (mkdocs.yml, docs/) into site/, strict: a warning fails
# the build (a broken link or anchor, a page missing from the nav, a generated table
# that no longer matches the code, a docstring the API reference cannot read).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
NO_MKDOCS_2_WARNING=1 .venv/bin/mkdocs build --strict --clean --site-dir site "$@"
