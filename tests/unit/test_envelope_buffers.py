"""`fcu.envelope.kept.Buffers`: a large array is handed out again only once nothing else
holds it (neither the array nor a view of it); each shape keeps its newest few."""

from __future__ import annotations

from fcu.envelope.kept import Buffers


def test_an_array_in_use_is_never_handed_out_again():
    buffers = Buffers(min_size=100, per_shape=4, max_shapes=8)
    a = buffers.take(10, 20)
    b = buffers.take(10, 20)
    assert a is not b  # `a` is held
    a_id = id(a)
    view = a[:, :5]
    del a
    c = buffers.take(10, 20)
    assert id(c) != a_id and c is not b  # a view holds the array too
    del view
    d = buffers.take(10, 20)
    assert id(d) == a_id  # now free: reused
    assert buffers.take(10, 20) is not d and buffers.take(20, 10).shape == (20, 10)


def test_each_shape_keeps_its_newest_few():
    buffers = Buffers(min_size=100, per_shape=2, max_shapes=8)
    held = [buffers.take(10, 10) for _ in range(4)]  # all held: four new arrays
    assert len({id(x) for x in held}) == 4
    kept = {id(x) for x in held[2:]}  # the two newest are kept, the older two let go
    del held
    again = buffers.take(10, 10)
    assert id(again) in kept
