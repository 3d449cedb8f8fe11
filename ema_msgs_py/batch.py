"""Several frames of one per-frame topic in one ``JointState``: the contract's batched form (an option).

Under lockstep a suite may send the frames of one clock grant as one message per topic (``ema launch
--frames-per-message K``): fewer messages, the same values. A batch is still a ``sensor_msgs/JointState``:

* ``header.frame_id`` is ``ema_frames:<count>:<step_ns>:<the frames' own frame_id>``;
* ``header.stamp`` is the first frame's stamp, frame ``i``'s is ``stamp + i * step_ns``;
* ``name`` and each array are the frames' own, concatenated in frame order (every frame has the same names
  and the same array lengths).

:func:`join` makes one, :func:`split` and :func:`split_raw` give the frames back exactly (the doubles are
copied, never recomputed), so a recorder writes the frames a per-frame suite would have sent, byte for byte.
A reader that does not know the form sees one message with repeated names: only suite nodes of the same
option should take these topics.
"""

from __future__ import annotations

from ema_msgs_py.cdr import JointFrame, decode, encode

PREFIX = "ema_frames:"
"""The batched form's ``frame_id`` prefix."""
_TAG = PREFIX.encode()
_AT = 16
"""Where a message's frame_id characters start: encapsulation header (4), stamp (8), the string's length (4)."""


def is_batch(raw: bytes | memoryview) -> bool:
    """Whether CDR bytes of a ``JointState`` hold a batch (a look at the frame_id's first characters).

    Parameters
    ----------
    raw : bytes or memoryview
        The serialized message.

    Returns
    -------
    bool
        True for a batch.
    """
    return bytes(raw[_AT:_AT + len(_TAG)]) == _TAG


def compatible(a: JointFrame, b: JointFrame) -> bool:
    """Whether ``b`` can follow ``a`` in one batch: the same names, frame_id and array lengths.

    Parameters
    ----------
    a, b : JointFrame
        Two frames.

    Returns
    -------
    bool
        True when they can share a batch (the stamps are checked by the caller).
    """
    return (a.name == b.name and a.frame_id == b.frame_id and len(a.position) == len(b.position)
            and len(a.velocity) == len(b.velocity) and len(a.effort) == len(b.effort))


def join(frames: list[JointFrame]) -> JointFrame:
    """Frames of equal layout, evenly stamped, as one batch (one frame: the frame itself).

    Parameters
    ----------
    frames : list of JointFrame
        At least one; each :func:`compatible` with the first, stamped one step apart.

    Returns
    -------
    JointFrame
        The batch.

    Raises
    ------
    ValueError
        Frames of different layouts or stamps not evenly spaced.
    """
    first = frames[0]
    if len(frames) == 1:
        return first
    step = frames[1].stamp_ns - first.stamp_ns
    if step <= 0 or any(f.stamp_ns != first.stamp_ns + i * step or not compatible(first, f)
                        for i, f in enumerate(frames)):
        raise ValueError("a batch takes frames of one layout, stamped evenly and increasing")
    return JointFrame(first.stamp_ns, [n for f in frames for n in f.name],
                      [v for f in frames for v in f.position], [v for f in frames for v in f.velocity],
                      [v for f in frames for v in f.effort], f"{PREFIX}{len(frames)}:{step}:{first.frame_id}")


def split(batch: JointFrame) -> list[JointFrame]:
    """The frames of a batch (a frame that is not one: itself).

    Parameters
    ----------
    batch : JointFrame
        A decoded message.

    Returns
    -------
    list of JointFrame
        Its frames, in order.

    Raises
    ------
    ValueError
        A malformed batch (its count or step unreadable, its arrays not a whole number of frames).
    """
    if not batch.frame_id.startswith(PREFIX):
        return [batch]
    try:
        count_text, step_text, frame_id = batch.frame_id[len(PREFIX):].split(":", 2)
        count, step = int(count_text), int(step_text)
    except ValueError:
        raise ValueError(f"malformed batch frame_id {batch.frame_id!r}") from None
    arrays = (batch.name, batch.position, batch.velocity, batch.effort)
    if count < 1 or step <= 0 or any(len(a) % count for a in arrays):
        raise ValueError(f"malformed batch: {count} frames, step {step} ns, arrays of {[len(a) for a in arrays]}")
    n, p, v, e = (len(a) // count for a in arrays)
    return [JointFrame(batch.stamp_ns + i * step, batch.name[i * n:(i + 1) * n], batch.position[i * p:(i + 1) * p],
                       batch.velocity[i * v:(i + 1) * v], batch.effort[i * e:(i + 1) * e], frame_id)
            for i in range(count)]


def split_raw(raw: bytes | memoryview) -> list[bytes]:
    """The CDR bytes of each frame of a batch, as a per-frame publisher would have sent them.

    Parameters
    ----------
    raw : bytes or memoryview
        A batch's CDR bytes (:func:`is_batch`).

    Returns
    -------
    list of bytes
        Each frame's CDR bytes.

    Raises
    ------
    ValueError
        Bytes that are no JointState, or a malformed batch.
    """
    return [encode(f) for f in split(decode(raw))]
