"""Shared test configuration.

Every test that proves a requirement carries its IDs: ``@pytest.mark.req("C14-11")``.
"""
