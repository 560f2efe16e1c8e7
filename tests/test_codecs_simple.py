import pytest

from cclogfs.codecs import codec_from_config, raw_size
from cclogfs.errors import CodecError, UnknownCodecError


@pytest.mark.parametrize("config", ["none", "zstd", {"id": "lzma", "preset": 1}])
def test_round_trip(config):
    codec = codec_from_config(config)
    stamps, texts = [1, 2, 2], [b'{"a":1}', b"", "\u00e9".encode()]
    data = codec.encode(stamps, texts)
    assert codec.decode(data, count=3, raw_len=raw_size(stamps, texts)) == (stamps, texts)


def test_unknown_codec():
    with pytest.raises(UnknownCodecError, match="unknown codec 'bogus'"):
        codec_from_config("bogus")


def test_zstd_bounded_by_header_not_frame():
    codec = codec_from_config("zstd")
    data = codec.encode([1], [b"x" * 1000])
    with pytest.raises(CodecError, match="more or less"):
        codec.decode(data, count=1, raw_len=100)
