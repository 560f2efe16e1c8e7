import pytest

from cclogfs.codecs import codec_from_config, raw_size
from cclogfs.errors import CodecError, UnknownCodecError


@pytest.mark.parametrize("config", ["none", "zstd", {"id": "lzma", "preset": 1}])
def test_round_trip(config):
    codec = codec_from_config(config)
    stamps, texts = [1, 2, 2], ['{"a":1}', "", "\u00e9"]
    data = codec.encode(stamps, texts)
    assert codec.decode(data, count=3, raw_len=raw_size(stamps, texts)) == (stamps, texts)


def test_unknown_codec():
    with pytest.raises(UnknownCodecError, match="unknown codec 'bogus'"):
        codec_from_config("bogus")


def test_zstd_bounded_by_header_not_frame():
    codec = codec_from_config("zstd")
    data = codec.encode([1], ["x" * 1000])
    with pytest.raises(CodecError, match="more or less"):
        codec.decode(data, count=1, raw_len=100)


def test_forged_frame_cannot_make_us_allocate_its_declared_size():
    # A small frame that declares (and really holds) 64 MiB; the checksummed header says the
    # window is 1 KiB. Decoding must fail having allocated about 1 KiB, not 64 MiB.
    import tracemalloc

    import zstandard

    bomb = zstandard.ZstdCompressor(level=1).compress(b"\0" * (64 << 20))
    assert zstandard.frame_content_size(bomb) == 64 << 20 and len(bomb) < 1 << 20
    codec = codec_from_config("zstd")
    tracemalloc.start()
    try:
        with pytest.raises(CodecError):
            codec.decode(bomb, count=1, raw_len=1024)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 << 20, f"decoding allocated {peak} bytes"


@pytest.mark.parametrize("config", ["zstd", "lzma", "columnar"])
def test_every_codec_refuses_payloads_larger_than_stated(config):
    codec = codec_from_config(config)
    stamps, texts = list(range(50)), ['{"v": %d.5}' % i for i in range(50)]
    data = codec.encode(stamps, texts)
    with pytest.raises(CodecError):
        codec.decode(data, count=50, raw_len=raw_size(stamps, texts) - 1)
