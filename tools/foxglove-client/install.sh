#!/usr/bin/env bash
# Installs the stock Foxglove WebSocket client the view's test runs (tests/tests/foxglove_view.rs):
# @foxglove/ws-protocol, ws and protobufjs, at the versions of package-lock.json, into
# tools/foxglove-client/node_modules. Needs node (20 or later) and npm.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
npm ci --no-audit --no-fund --loglevel=error
