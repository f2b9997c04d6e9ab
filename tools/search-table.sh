#!/usr/bin/env bash
exec python3 "$(dirname "$0")/tables.py" search-table "$@"
