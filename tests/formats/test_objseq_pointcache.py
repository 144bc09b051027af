"""OBJ zip sequences and OBJ + PC2/MDD point caches, written by the tests; zip safety; bad caches."""

from __future__ import annotations

import io
import stat
import struct
import zipfile

import numpy as np
import pytest

from converter.errors import InputError
from converter.formats import load
from converter.formats.objseq import load_zip
from converter.formats.pointcache import load_obj_cache

REST = np.float32([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]])


def obj_text(v: np.ndarray, faces: bool = True) -> str:
    lines = ["mtllib face.mtl", "o face"] + [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v]
    if faces:
        lines += ["usemtl Skin", "f 1 2 3 4", "usemtl Eye_L", "f 1/1/1 2/2/2 5/5/5"]
    return "\n".join(lines) + "\n"


def frame(k: int) -> np.ndarray:
    return REST + np.float32([0, 0, 0.1 * k])


def zip_bytes(entries: dict[str, bytes], symlink: str | None = None) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in entries.items():
            info = zipfile.ZipInfo(name)
            info.compress_type = zipfile.ZIP_DEFLATED
            if name == symlink:
                info.external_attr = (stat.S_IFLNK | 0o777) << 16
            zf.writestr(info, data)
    return buf.getvalue()


def test_obj_zip_in_natural_order_with_parts_and_mtl_colours(tmp_path):
    # Names that sort wrongly as text (frame10 before frame2) and a folder prefix.
    entries = {f"anim/frame{k}.obj": obj_text(frame(k)).encode() for k in (10, 2, 1, 0)}
    entries["anim/face.mtl"] = b"newmtl Skin\nKd 0.8 0.5 0.4\nnewmtl Eye_L\nKd 1 1 1\n"
    entries["__MACOSX/._frame1.obj"] = b"junk"
    path = tmp_path / "seq.zip"
    path.write_bytes(zip_bytes(entries))
    a = load(path, fps=12)
    assert (a.n_frames, a.fps, a.n_faces) == (4, 12.0, 3)
    np.testing.assert_allclose(a.frames[:, 4, 2], [1.0, 1.1, 1.2, 2.0], atol=1e-6)
    assert [(p.name, p.color) for p in a.parts] == [("skin", (0.8, 0.5, 0.4)), ("eye", (1.0, 1.0, 1.0))]
    assert a.part_ids.tolist() == [0, 0, 1]
    assert load_zip(path.read_bytes()).fps == 30.0


def test_obj_frames_with_different_vertex_counts_name_the_frame():
    entries = {"f1.obj": obj_text(frame(1)).encode(), "f2.obj": obj_text(REST[:4], faces=False).encode()}
    with pytest.raises(InputError, match="f2.obj has 4 vertices"):
        load_zip(zip_bytes(entries))


def test_obj_zip_nan_and_no_frames():
    bad = frame(1).copy()
    bad[2, 1] = np.inf
    with pytest.raises(InputError, match="NaN or infinite"):
        load_zip(zip_bytes({"1.obj": obj_text(REST).encode(), "2.obj": obj_text(bad).encode()}))
    with pytest.raises(InputError, match="no .obj"):
        load_zip(zip_bytes({"readme.txt": b"hello"}))


@pytest.mark.parametrize("name", ["../evil.obj", "/etc/evil.obj", "a/../../evil.obj", "C:/evil.obj"])
def test_zip_traversal_is_refused(name):
    with pytest.raises(InputError, match="absolute path or '..'"):
        load_zip(zip_bytes({"1.obj": obj_text(REST).encode(), name: b"v 0 0 0\n"}))


def test_zip_symlink_is_refused():
    with pytest.raises(InputError, match="symbolic link"):
        load_zip(zip_bytes({"1.obj": obj_text(REST).encode(), "link.obj": b"/etc/passwd"}, symlink="link.obj"))


def test_zip_bomb_is_refused_before_inflating():
    with pytest.raises(InputError, match="decompression bomb"):
        load_zip(zip_bytes({"1.obj": obj_text(REST).encode(), "2.obj": b" " * (8 << 20)}))


def test_zip_with_too_many_entries_is_refused(monkeypatch):
    import converter.formats.objseq as objseq

    monkeypatch.setattr(objseq, "MAX_ENTRIES", 3)
    with pytest.raises(InputError, match="entries"):
        load_zip(zip_bytes({f"{k}.obj": obj_text(REST).encode() for k in range(4)}))


def test_truncated_zip():
    data = zip_bytes({"1.obj": obj_text(REST).encode()})
    with pytest.raises(InputError):
        load_zip(data[: len(data) // 2])


def pc2(frames: np.ndarray, rate: float = 1.0, start: float = 0.0) -> bytes:
    head = struct.pack("<12siiffi", b"POINTCACHE2\0", 1, frames.shape[1], start, rate, len(frames))
    return head + frames.astype("<f4").tobytes()


def mdd(frames: np.ndarray, times: np.ndarray) -> bytes:
    header = struct.pack(">ii", len(frames), frames.shape[1])
    return header + times.astype(">f4").tobytes() + frames.astype(">f4").tobytes()


def test_pc2_one_sample_per_frame_and_sample_rate():
    frames = np.stack([frame(k) for k in range(5)])
    a = load_obj_cache(obj_text(REST).encode(), pc2(frames), name="pc2")
    assert (a.n_frames, a.fps) == (5, 30.0)
    np.testing.assert_allclose(a.frames, frames, atol=1e-6)
    # Two samples per scene frame (sampleRate 0.5) resampled to 30 fps keeps every second sample.
    half = load_obj_cache(obj_text(REST).encode(), pc2(frames, rate=0.5), fps=30.0)
    np.testing.assert_allclose(half.frames, frames[::2], atol=1e-6)
    assert load_obj_cache(obj_text(REST).encode(), pc2(frames, rate=0.5)).fps == 60.0


def test_mdd_times_resampled_to_requested_fps():
    frames = np.stack([frame(k) for k in range(3)])
    a = load_obj_cache(obj_text(REST).encode(), mdd(frames, np.float32([0, 0.5, 1.0])), fps=4.0)
    assert a.n_frames == 5
    np.testing.assert_allclose(a.frames[:, 4, 2], [1.0, 1.05, 1.1, 1.15, 1.2], atol=1e-6)
    assert load_obj_cache(obj_text(REST).encode(), mdd(frames, np.float32([0, 0.5, 1.0]))).fps == 2.0


def test_blender_z_up_mdd_is_detected_and_brought_to_the_obj_axes():
    frames = np.stack([frame(k) for k in range(3)])
    # Blender's exporter writes its Z-up world (x, -z_obj, y_obj) while its OBJ is Y-up.
    zup = np.stack([frames[..., 0], -frames[..., 2], frames[..., 1]], axis=-1)
    times = np.float32([0, 1, 2]) / 25
    a = load_obj_cache(obj_text(REST).encode(), mdd(zup, times))
    assert a.fps == 25.0
    np.testing.assert_allclose(a.frames, frames, atol=1e-6)
    forced = load_obj_cache(obj_text(REST).encode(), mdd(zup, times), axes="none")
    np.testing.assert_allclose(forced.frames, zup, atol=1e-6)


def test_obj_plus_cache_in_a_zip_and_cache_flag(tmp_path):
    frames = np.stack([frame(k) for k in range(4)])
    a = load_zip(zip_bytes({"face.obj": obj_text(REST).encode(), "face.pc2": pc2(frames)}))
    assert a.n_frames == 4
    (tmp_path / "face.obj").write_text(obj_text(REST))
    (tmp_path / "face.mdd").write_bytes(mdd(frames, np.arange(4, dtype=np.float32) / 30))
    b = load(tmp_path / "face.obj", cache=tmp_path / "face.mdd")
    np.testing.assert_allclose(b.frames, frames, atol=1e-6)


@pytest.mark.parametrize("cache, match", [
    (pc2(np.zeros((2, 4, 3))), "4 points but the OBJ has 5"),
    (mdd(np.zeros((2, 6, 3)), np.float32([0, 1])), "6 points but the OBJ has 5"),
    (pc2(np.zeros((2, 5, 3)))[:-4], "truncated"),
    (mdd(np.zeros((2, 5, 3)), np.float32([0, 1]))[:-4], "truncated"),
    (struct.pack("<12siiffi", b"POINTCACHE2\0", 1, 5, 0, 1, 0), "0 samples"),
    (struct.pack(">ii", 0, 5), "0 frames"),
    (pc2(np.full((2, 5, 3), np.nan)), "NaN"),
    (b"xy", "neither PC2 nor"),
])
def test_bad_point_caches(cache, match):
    with pytest.raises(InputError, match=match):
        load_obj_cache(obj_text(REST).encode(), cache)


def test_dispatcher_recognises_inputs_by_content(tmp_path):
    from converter.formats import sniff

    assert sniff(b"\xef\xbb\xbf  {\"asset\": {}}") == "gltf"
    assert sniff(b"glTF\x02\x00\x00\x00") == "glb"
    assert sniff(zip_bytes({"1.obj": b"v 0 0 0\n"})) == "zip"
    assert sniff(obj_text(REST).encode()) == "obj"
    with pytest.raises(InputError, match="PC2 point cache"):
        sniff(pc2(np.zeros((1, 5, 3))))
    with pytest.raises(InputError, match="not a glTF"):
        sniff(b"\x00\x01garbage")
    (tmp_path / "face.obj").write_text(obj_text(REST))
    still = load(tmp_path / "face.obj")  # an OBJ on its own is a one-frame face
    assert still.n_frames == 1 and np.allclose(still.frames[0], REST)


def test_random_byte_flips_of_zips_and_caches_give_input_error_or_load():
    rng = np.random.default_rng(11)
    moving = np.stack([frame(k) for k in range(4)])
    sources = [zip_bytes({f"f{k}.obj": obj_text(frame(k)).encode() for k in range(4)}),
               zip_bytes({"face.obj": obj_text(REST).encode(), "face.pc2": pc2(moving)}),
               pc2(moving), mdd(moving, np.float32([0, 1, 2, 3]) / 30)]
    for it in range(400):
        kind = it % 4
        data = bytearray(sources[kind])
        for pos in rng.integers(0, len(data), rng.integers(1, 6)):
            data[pos] = int(rng.integers(0, 256))
        try:
            if kind < 2:
                load_zip(bytes(data))
            else:
                load_obj_cache(obj_text(REST).encode(), bytes(data))
        except InputError:
            pass


def test_float32_times_do_not_lose_the_last_frame():
    frames = np.repeat(REST[None], 330, axis=0)
    times = (np.arange(330) / 30).astype(np.float32)  # 329/30 rounds below its exact value in float32
    a = load_obj_cache(obj_text(REST).encode(), mdd(frames, times))
    assert (a.n_frames, a.fps) == (330, 30.0)
