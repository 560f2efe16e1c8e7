"""cclogfs.export.jsonschema: the schema MCAP's "jsonschema" encoding carries for a stream."""

import json

import pytest

from cclogfs.export.jsonschema import message_schema, schema_of


@pytest.mark.parametrize(
    "value, schema",
    [
        (True, {"type": "boolean"}),  # a bool is not a number, though Python says it is an int
        (3, {"type": "number"}),
        (2.5, {"type": "number"}),
        ("s", {"type": "string"}),
        (None, {}),
        ([], {"type": "array"}),
        ([1, 2], {"type": "array", "items": {"type": "number"}}),
        ({}, {"type": "object", "properties": {}}),
    ],
)
def test_schema_of_each_json_type(value, schema):
    assert schema_of(value) == schema


def test_schema_of_nested_message_describes_without_requiring():
    schema = schema_of({"pose": {"x": 1.0, "ok": False}, "tags": [["a"]], "note": None})
    assert schema == {
        "type": "object",
        "properties": {
            "pose": {"type": "object", "properties": {"x": {"type": "number"}, "ok": {"type": "boolean"}}},
            "tags": {"type": "array", "items": {"type": "array", "items": {"type": "string"}}},
            "note": {},
        },
    }
    assert "required" not in json.dumps(schema) and "additionalProperties" not in json.dumps(schema)


def test_message_schema_is_a_titled_utf8_document():
    doc = json.loads(message_schema('{"name": "é", "v": [1]}', "/odom"))
    assert doc["$schema"].startswith("https://json-schema.org/") and doc["title"] == "/odom"
    assert doc["type"] == "object" and doc["properties"]["v"] == {"type": "array", "items": {"type": "number"}}
    assert message_schema("[]", "t").decode("utf-8")


def test_message_schema_of_bad_json_raises():
    with pytest.raises(ValueError):
        message_schema("{not json", "/odom")
