#!/usr/bin/env bash
# What `make test` needs beyond .venv: PostgreSQL's server programs for the sweep's tracking-server test
# (tests/test_sweep.py starts its own server on 127.0.0.1; the S3 server and Ray come with requirements.txt).
# Installed here when missing and this runs as root with apt-get (Debian/Ubuntu); otherwise the test is skipped with
# a message naming PostgreSQL, or fails under LFDT_REQUIRE_SERVICES=1 (as in .ci/run).
set -uo pipefail
if command -v initdb >/dev/null || compgen -G "/usr/lib/postgresql/*/bin/initdb" >/dev/null; then
  exit 0
fi
if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null; then
  echo "make test: installing PostgreSQL's server programs (apt-get install postgresql) for tests/test_sweep.py" >&2
  if apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq postgresql >/dev/null; then
    exit 0
  fi
  echo "make test: could not install PostgreSQL (apt-get install postgresql)" >&2
else
  echo "make test: PostgreSQL is not installed and cannot be installed here (needs root and apt-get):" \
       "tests/test_sweep.py's tracking-server tests will be skipped (Debian: sudo apt-get install postgresql)" >&2
fi
# a missing PostgreSQL fails the run only where the tests are told to require it
[ "${LFDT_REQUIRE_SERVICES:-0}" = "1" ] && exit 1
exit 0
