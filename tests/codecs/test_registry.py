"""cclogfs.codecs.registry: codec ids (config string, header number) to codec classes."""

import json

import pytest

from cclogfs.codecs.registry import CodecId, codec_for_record, codec_from_config, codec_numeric_id, registered_ids
from cclogfs.errors import CodecError, UnknownCodecError


def test_every_registered_id_builds_its_codec_with_a_fixed_number():
    ids = registered_ids()
    assert ids == sorted(ids) and {"zstd", "columnar"} <= set(ids)
    numbers = {}
    for codec_id in ids:
        codec = codec_from_config(codec_id)
        assert codec.codec_id == codec_id and codec.get_config()["id"] == codec_id
        numbers[codec_id] = codec_numeric_id(codec)
    assert numbers["columnar"] == CodecId.COLUMNAR == 4  # on disk: never changes
    assert len(set(numbers.values())) == len(numbers) and 0 not in numbers.values()


def test_a_config_round_trips_through_get_config():
    codec = codec_from_config("columnar")
    again = codec_from_config(codec.get_config())
    assert again.get_config() == codec.get_config()


def test_an_unknown_codec_names_the_known_ones():
    with pytest.raises(UnknownCodecError, match="unknown codec 'brotli'; known codecs: .*columnar"):
        codec_from_config({"id": "brotli"})


@pytest.mark.parametrize("config", [{}, {"id": 4}, ["columnar"], None])
def test_a_config_without_a_string_id_is_refused(config):
    with pytest.raises(CodecError, match="string 'id'"):
        codec_from_config(config)


def test_codec_for_record_builds_one_codec_per_distinct_config():
    config = json.dumps(codec_from_config("columnar").get_config()).encode()
    assert codec_for_record(config) is codec_for_record(config)
    assert codec_for_record(b'{"id":"zstd"}').codec_id == "zstd"
    with pytest.raises(UnknownCodecError):
        codec_for_record(b'{"id":"nope"}')
