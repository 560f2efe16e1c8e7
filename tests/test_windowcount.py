"""How records are joined into the windows a user counts (`cclogfs.windowcount`): each rule
once, the kinds of records that may come between, and a record whose predecessor was not
read (an export cut to --start/--end)."""

from cclogfs.windowcount import WindowCount, WindowJoiner, count_records, link_of


def smart(wid, part, **more):
    return link_of({"window_id": wid, "part": part, **more})


ALL = link_of({"kind": "all"})
SUMMARY = link_of({"kind": "summary"})


def test_a_smart_windows_parts_on_several_topics_are_one_window():
    count = WindowCount()
    for stream, link in [("/odom", smart("w5", 0)), ("/tf", smart("w5", 0)), ("/cclog/summary", SUMMARY),
                         ("/odom", smart("w5", 1)), ("/tf", smart("w5", 1)), ("/tf_static", smart("w5", 0)),
                         ("/odom", smart("w9", 0))]:  # fmt: skip
        count.add(stream, link)
    assert (count.windows, count.summaries, count.records) == (2, 1, 6)
    assert count.streams == {"/odom": 2, "/tf": 1, "/tf_static": 1, "/cclog/summary": 1}
    assert count.joined == {("/tf", "part"): 2, ("/odom", "part"): 1, ("/tf_static", "part"): 1}


def test_the_same_window_id_again_from_part_0_is_another_window():
    # the same stamps recorded twice (--append): the ids repeat, the parts start again
    joiner = WindowJoiner()
    got = [joiner.join(s, link)[0] for s, link in [("/odom", smart("w5", 0)), ("/odom", smart("w5", 1)),
                                                   ("/odom", smart("w5", 0)), ("/tf", smart("w5", 0))]]
    assert got == [1, 1, 2, 2]


def test_records_between_a_smart_windows_parts_change_nothing():
    # odometry the model could not score, summaries: kept apart while the window is open
    count = WindowCount()
    for stream, link in [("/odom", smart("w5", 0)), ("/odom", link_of({"kind": "unscored"})),
                         ("/cclog/summary", SUMMARY), ("/odom", smart("w5", 1))]:  # fmt: skip
        count.add(stream, link)
    assert (count.windows, count.summaries, count.streams["/odom"]) == (2, 1, 2)


def test_a_window_whose_stamps_go_back_is_one_window():
    split = [(4, "/odom", link_of({"kind": "all", "split": [0, 2]}), False),
             (5, "/odom", link_of({"kind": "all", "split": [1, 2]}), False),
             (6, "/odom", ALL, False)]  # fmt: skip
    count = count_records(reversed(split))  # any order: sorted by seq
    assert (count.windows, count.records, count.joined) == (2, 3, {("/odom", "split"): 1})


def test_the_stores_parts_over_its_record_limit_are_one_window():
    count = count_records([(7, "/odom", ALL, True), (8, "/odom", ALL, True), (9, "/odom", ALL, False),
                           (10, "/odom", ALL, False)])  # fmt: skip
    assert (count.windows, count.records, count.joined) == (2, 4, {("/odom", "limit"): 2})


def test_only_the_record_just_before_is_continued():
    # cut to --start/--end, the first record of a window whose stamps go back may not be
    # exported: its second does not join the window exported before it
    count = count_records([(1, "/odom", ALL, False), (3, "/odom", link_of({"kind": "all", "split": [1, 2]}), False),
                           (4, "/tf", ALL, False)])  # fmt: skip
    assert count.windows == 3
    # a PART record continues only its own stream's next record
    assert count_records([(1, "/odom", ALL, True), (2, "/tf", ALL, False)]).windows == 2


def test_a_pending_window_counts_its_records():
    count = WindowCount()
    count.add("/odom", ALL, records=3)  # put once, stored as 3 records (the pipeline)
    count.add("/odom", smart("w1", 0), records=2)
    count.add("/odom", smart("w1", 1))
    assert (count.windows, count.records, count.stream_records) == (2, 6, {"/odom": 6})
