"""Canonical JSON and its SHA-256: the text of a config that is stored and hashed (product
keys, dataset provenance)."""

import hashlib
import json


def canonical_json(value) -> str:
    """Key-sorted compact JSON: the text that is hashed and stored."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def sha256(value) -> str:
    return hashlib.sha256(canonical_json(value).encode()).hexdigest()
