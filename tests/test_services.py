"""What a test does when a server program it starts is missing: skipped with the missing piece named, or failed where
the run requires every service (LFDT_REQUIRE_SERVICES=1, as .ci/run sets)."""

import pytest
import services


def _missing(name: str) -> str:
    raise RuntimeError(f"PostgreSQL's {name} is not installed (Debian: apt-get install postgresql)")


def test_missing_postgres_skips_naming_it(monkeypatch):
    monkeypatch.setattr(services, "_pg_bin", _missing)
    monkeypatch.delenv(services.REQUIRE_ENV, raising=False)
    with pytest.raises(pytest.skip.Exception, match="PostgreSQL's initdb is not installed"):
        services.require_postgres()


def test_missing_postgres_fails_where_services_are_required(monkeypatch):
    monkeypatch.setattr(services, "_pg_bin", _missing)
    monkeypatch.setenv(services.REQUIRE_ENV, "1")
    with pytest.raises(RuntimeError, match="PostgreSQL's initdb"):
        services.require_postgres()


def test_installed_postgres_neither_skips_nor_fails(monkeypatch):
    monkeypatch.setattr(services, "_pg_bin", lambda name: f"/usr/bin/{name}")
    services.require_postgres()
