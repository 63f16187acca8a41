"""rigsim.dataset.store without rendering: checksums, image bytes, the frame's two files and when a frame is
trusted. Expected values from hashlib, json and OpenCV/astropy directly."""

import hashlib
import json
import os

import numpy as np
import pytest

from rigsim.dataset import store
from rigsim.errors import DatasetError, InputError

IMG = (np.arange(24 * 40, dtype=np.uint16).reshape(24, 40) * 37) % 4096


def test_checksums_are_sha256_of_the_bytes_and_of_canonical_json(tmp_path):
    data = os.urandom((1 << 20) + 12345)  # more than one read chunk
    (tmp_path / "b").write_bytes(data)
    assert store.sha256_file(tmp_path / "b") == store.sha256_bytes(data) == hashlib.sha256(data).hexdigest()
    a = {"b": [1, 2.5, "x"], "a": {"z": None, "y": True}}
    b = {"a": {"y": True, "z": None}, "b": [1, 2.5, "x"]}
    assert store.canonical_sha256(a) == store.canonical_sha256(b) == hashlib.sha256(
        b'{"a":{"y":true,"z":null},"b":[1,2.5,"x"]}').hexdigest()
    assert store.canonical_sha256({"a": 1}) != store.canonical_sha256({"a": 2})


@pytest.mark.parametrize("fmt", ["png", "fits"])
def test_images_round_trip_bit_exact(tmp_path, fmt):
    p = tmp_path / f"f.{fmt}"
    p.write_bytes(store.encode_image(IMG, fmt, [("OBJECT", "t", "a card")] if fmt == "fits" else None))
    back = store.decode_image(p)
    assert back.dtype == np.uint16 and np.array_equal(back, IMG)
    if fmt == "png":
        import cv2

        assert np.array_equal(cv2.imread(str(p), cv2.IMREAD_UNCHANGED), IMG)


def test_bad_images_are_refused(tmp_path):
    for dtype in (np.uint8, np.int32, np.float64):
        with pytest.raises(ValueError, match="2-D uint16"):
            store.encode_image(IMG.astype(dtype), "png")
    for bad in (IMG[None], IMG.ravel()):
        with pytest.raises(ValueError, match="2-D uint16"):
            store.encode_image(bad, "png")
    for fmt in ("bmp", "fit", "tif"):
        with pytest.raises(ValueError, match="must be 'png' or 'fits'"):
            store.encode_image(IMG, fmt)
    with pytest.raises(ValueError, match="'tif': must be 'png' or 'fits'"):
        store.encode_image(IMG, "tif")
    (tmp_path / "frame.a").write_bytes(store.encode_image(IMG, "png"))  # a name that is no frame's: refused
    with pytest.raises(InputError, match=r"frame\.a: unsupported dataset frame file type '\.a'; expected one of \.png"):
        store.decode_image(tmp_path / "frame.a")
    (tmp_path / "x.png").write_bytes(b"\x89PNG\r\n\x1a\n broken")
    with pytest.raises(InputError, match=r"x\.png: not a readable PNG image"):
        store.decode_image(tmp_path / "x.png")


def _write(root, index=7, value=3, params=None):
    img = IMG + value
    return img, store.write_frame_atomic(root, index, img, {"seed": value, "truth": {"u": 1.5}}, "png", params=params)


def test_a_frame_is_its_image_then_a_sidecar_naming_the_images_checksum(tmp_path):
    params = {"seed": 3, "pose": [1.0, 2.0]}
    img, digest = _write(tmp_path, params=params)
    ip, jp = store.frame_files(tmp_path, 7, "png")
    assert (ip.name, jp.name, ip.parent.name) == ("frame_000007.png", "frame_000007.json", "frames")
    assert digest == hashlib.sha256(ip.read_bytes()).hexdigest()
    sc = json.loads(jp.read_text())
    ds = sc["dataset"]
    assert ds["index"] == 7 and ds["image_file"] == "frame_000007.png" and ds["image_sha256"] == digest
    assert ds["params_sha256"] == store.canonical_sha256(params)
    want = ds.pop("sidecar_sha256")
    assert want == store.canonical_sha256(sc) and sc["seed"] == 3 and sc["truth"] == {"u": 1.5}
    assert store.sidecar_problem(jp, 7, params) is None
    assert store.frame_complete(tmp_path, 7, "png", params=params)
    assert np.array_equal(store.decode_image(ip), img)


def test_when_a_frame_is_not_trusted(tmp_path):
    params = {"seed": 3}
    _write(tmp_path, params=params)
    ip, jp = store.frame_files(tmp_path, 7, "png")
    good = jp.read_text()
    assert store.sidecar_problem(jp, 8) == store.sidecar_problem(jp, 6) == "written for frame 7"
    assert store.sidecar_problem(jp, 7, {"seed": 4}) == "written for another plan (pose, seed or options differ)"
    assert not store.frame_complete(tmp_path, 7, "png", params={"seed": 4})
    assert not store.frame_complete(tmp_path, 8, "png")
    want = json.loads(good)["dataset"]["sidecar_sha256"]
    order = set()
    for u in np.arange(2.5, 12.5):  # edits whose checksums fall on both sides of the written one
        sc = json.loads(good)
        sc["truth"]["u"] = float(u)
        jp.write_text(json.dumps(sc))
        assert store.sidecar_problem(jp, 7) == "edited after it was written (its own checksum does not match)"
        sc["dataset"].pop("sidecar_sha256")
        order.add(store.canonical_sha256(sc) < want)
    assert order == {True, False}
    for text in ("{", "[]", '{"dataset": {}}', '{"dataset": {"sidecar_sha256": 1, "image_sha256": "a"}}',
                 '{"dataset": {"sidecar_sha256": "a"}}'):
        jp.write_text(text)
        assert store.sidecar_problem(jp, 7) in ("unreadable or not written by rigsim dataset generate", "no checksums"), text
        assert not store.frame_complete(tmp_path, 7, "png")
    jp.write_text(good)
    ip.write_bytes(store.encode_image(IMG + 9, "png"))  # a whole image, not the one the sidecar names
    assert not store.frame_complete(tmp_path, 7, "png", params=params)
    assert store.frame_complete(tmp_path, 7, "png", verify=False, params=params)  # only a full check hashes it
    ip.unlink()
    assert not store.frame_complete(tmp_path, 7, "png", verify=False)
    _write(tmp_path, params=params)
    jp.unlink()
    assert not store.frame_complete(tmp_path, 7, "png", verify=False)


def test_links_are_never_trusted(tmp_path):
    _write(tmp_path, index=1)
    other = tmp_path / "other"
    other.mkdir()
    _write(other, index=1)
    for name in ("frame_000001.png", "frame_000001.json"):
        ip = tmp_path / "frames" / name
        ip.rename(tmp_path / "keep")
        os.symlink(other / "frames" / name, ip)
        assert not store.frame_complete(tmp_path, 1, "png")
        ip.unlink()
        (tmp_path / "keep").rename(ip)
    assert store.frame_complete(tmp_path, 1, "png")


def test_read_json_names_a_missing_or_corrupt_file(tmp_path):
    with pytest.raises(DatasetError, match=r"plan\.json: missing \(the plan\)"):
        store.read_json(tmp_path / "plan.json", "the plan")
    (tmp_path / "plan.json").write_text("{")
    with pytest.raises(DatasetError, match=r"plan\.json: line 1, column 2: not valid JSON \(.*\); expected the plan"):
        store.read_json(tmp_path / "plan.json", "the plan")
    store.atomic_write_json(tmp_path / "plan.json", {"a": np.float64(1.5), "b": np.arange(2)})
    assert store.read_json(tmp_path / "plan.json", "the plan") == {"a": 1.5, "b": [0, 1]}
