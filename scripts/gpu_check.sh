#!/usr/bin/env bash
# The GPU check (scripts/gpu_check.py says what it runs): scripts/gpu_check.sh [OUT] [--store STORE]
exec python3 "$(dirname "$0")/gpu_check.py" "$@"
