"""Photo files → 3D skeleton (``bodies.reconstruct_body_from_photos``, ``socialcam bodies``):
the glue between capture times, a COLMAP model of the photos, raw (distorted) 2D joints and
``reconstruct_body``. The photos are simulated (``synth.photos``, CMU walking); the model is
written in COLMAP's text format with a radial lens, so a chain that forgets to undistort the
joints, or pairs a photo with another photo's camera or time, is measurably off."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from scipy.spatial.transform import Rotation

from socialcam import bodies
from socialcam.bodies import reconstruct_body, reconstruct_body_from_photos
from socialcam.cli import main
from socialcam.mocap import load_bvh
from socialcam.synth.photos import BODY_JOINTS, BODY_PAIRS, photo_collection

DATA = Path(__file__).parent / "data" / "mocap"
#: SIMPLE_RADIAL coefficient of the simulated lenses (a wide-angle lens)
K1 = -0.25


@pytest.fixture(scope="module")
def clips():
    return [load_bvh(DATA / f"cmu_{n}300.bvh") for n in ("131_01_walk", "131_02_walk")]


def _distort(uv, K):
    """Raw pixels of undistorted pinhole pixels ``(..., 2)`` through the SIMPLE_RADIAL lens."""
    f, c = K[0, 0], K[:2, 2]
    n = (uv - c) / f
    r2 = (n**2).sum(-1, keepdims=True)
    return n * (1 + K1 * r2) * f + c


def _scene(tmp_path, clips, seed, extra=2, unit=1.0):
    """``photo_collection`` written as files: PNG photos (blank, the right size), a COLMAP
    text model of all but ``extra`` of them, a times CSV and a joints NPZ of raw pixels.
    The photo files are named in shuffled order so that file order ≠ capture order; the
    paths, with their times and raw joints, are returned in file name order (``names[f]``
    is photo ``f`` of the collection)."""
    m, m2 = clips
    pc = photo_collection(m.positions, m.names, m.fps, other=m2.positions, seed=seed)
    F = len(pc.cameras)
    W, H = pc.size
    rng = np.random.default_rng(seed)
    names = [f"IMG_{i:04d}.png" for i in rng.permutation(F + extra)]
    photos = tmp_path / "photos"
    photos.mkdir()
    blank = Image.new("RGB", (W, H))
    for n in names:
        blank.save(photos / n)
    model = tmp_path / "model"
    model.mkdir()
    cam_lines, img_lines = [], []
    for f in range(F):
        K, R, C = pc.cameras.K[f], pc.cameras.R[f], pc.cameras.C[f]
        # COLMAP's pixel centres are at +0.5 of OpenCV's
        cam_lines.append(f"{f + 1} SIMPLE_RADIAL {W} {H} {K[0, 0]} {K[0, 2] + 0.5} "
                         f"{K[1, 2] + 0.5} {K1}")  # fmt: skip
        x, y, z, w = Rotation.from_matrix(R).as_quat()
        t = -R @ C / unit  # a model in units of ``unit`` metres (SfM's scale is free)
        img_lines.append(f"{f + 1} {w} {x} {y} {z} {t[0]} {t[1]} {t[2]} {f + 1} {names[f]}\n")
    (model / "cameras.txt").write_text("\n".join(cam_lines) + "\n")
    (model / "images.txt").write_text("\n".join(img_lines) + "\n")
    (model / "points3D.txt").write_text("")
    t0 = 1000.0 + rng.uniform(0, 100)  # any clock
    times = np.r_[pc.cameras.times, rng.uniform(0, 2, extra)] + t0
    (tmp_path / "times.csv").write_text(
        "photo,seconds\n"
        + "".join(f"{n},{float(t)!r}\n" for n, t in zip(names, times, strict=True))
    )
    raw = [_distort(d, pc.cameras.K[f]) for f, d in enumerate(pc.detections)]
    raw += [np.zeros((0, len(BODY_JOINTS), 2))] * extra
    np.savez(tmp_path / "joints.npz", **dict(zip(names, raw, strict=True)))
    at = np.argsort(names)  # the paths in file name order, the unregistered among the others
    paths = [photos / names[i] for i in at]
    return pc, paths, names, times[at], [raw[i] for i in at], model


def _direct(pc, order):
    """``reconstruct_body`` on the simulator's undistorted detections and cameras, the
    photos in ``order`` (the fold assignment of the swap repair follows the photo order)."""
    dets = [pc.detections[f] for f in order]
    return reconstruct_body(dets, pc.cameras[np.asarray(order)], BODY_PAIRS).points


def _read_csv(path, F):
    J = len(BODY_JOINTS)
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == F * J
    pts = np.array([[float(r[k]) if r[k] else np.nan for k in "xyz"] for r in rows])
    return rows, pts.reshape(F, J, 3)


@pytest.mark.parametrize("seed", [0, 3])
def test_cli_reconstructs_the_walk_from_photo_files(tmp_path, clips, seed):
    pc, paths, names, times, _raw, model = _scene(tmp_path, clips, seed)
    F = len(pc.cameras)
    out = tmp_path / "out"
    args = [str(p) for p in paths]
    argv = ["bodies", *args, "--out", str(out), "--model", str(model)]
    argv += ["--times", str(tmp_path / "times.csv"), "--joints", str(tmp_path / "joints.npz")]
    assert main(argv) == 0
    report = json.loads((out / "report.json").read_text())
    assert sorted(report["skipped"]) == sorted(names[F:])
    assert report["photos"] == sorted(names[:F])
    rows, pts = _read_csv(out / "body.csv", F)
    # rows in the order of the photos given; truth by photo name
    order = [names.index(r["photo"]) for r in rows[:: len(BODY_JOINTS)]]
    truth = pc.points[order]
    err = np.linalg.norm(pts - truth, axis=-1)
    # the same collection straight through reconstruct_body (undistorted pixels, the
    # simulator's cameras): the files, lens and clock change nothing
    direct = _direct(pc, order)
    assert np.nanmax(np.abs(pts - direct)) < 1e-4
    t_csv = np.array([float(r["time_s"]) for r in rows[:: len(BODY_JOINTS)]])
    by_path = {p.name: t for p, t in zip(paths, times, strict=True)}
    expect = np.array([by_path[names[f]] for f in order]) - times.min()
    np.testing.assert_allclose(t_csv, expect, atol=1e-6)
    # measured 19.2 / 18.8 mm (seeds 0 / 3) as in test_bodies
    assert np.nanmedian(err) < 0.03, np.nanmedian(err)
    assert report["swaps_repaired"] > 0 and report["photos_with_person"] >= 0.9 * F
    assert (out / "body.png").stat().st_size > 10_000


def test_the_lens_is_undone_before_the_geometry(tmp_path, clips, monkeypatch):
    """Red check of the glue: the raw joints fed to ``reconstruct_body`` without the
    model's undistortion move the skeleton away from the reconstruction of the undistorted
    pixels by centimetres (the people stand near the middle of the photos, where the lens
    moves the joints by 0.5 px median and 5-8 px at the 90th percentile)."""
    pc, paths, names, times, raw, model = _scene(tmp_path, clips, 1)
    res = reconstruct_body_from_photos(paths, times=times, model=model, joints=raw)
    by_name = {n: f for f, n in enumerate(names[: len(pc.cameras)])}
    idx = [by_name[Path(p).name] for p in res.photos]
    direct = _direct(pc, idx)
    good = np.linalg.norm(res.body.points - direct, axis=-1)
    monkeypatch.setattr(type(res.cameras), "undistort_points", lambda self, x: np.asarray(x))
    bad_res = reconstruct_body_from_photos(paths, times=times, model=model, joints=raw)
    bad = np.linalg.norm(bad_res.body.points - direct, axis=-1)
    truth = pc.points[idx]
    err = [np.nanmedian(np.linalg.norm(r.body.points - truth, axis=-1)) for r in (res, bad_res)]
    print(np.nanmax(good), np.nanpercentile(bad, [50, 90]), err)
    assert np.nanmax(good) < 1e-4
    assert np.nanpercentile(bad, 90) > 0.01, np.nanpercentile(bad, 90)
    assert err[1] > err[0], err


def test_detector_and_sfm_paths(tmp_path, clips, monkeypatch):
    """Without ``joints`` the registered photos go to ``detect_body_joints`` (as files, in
    order); without ``model`` the photos are linked into ``work_dir/images`` for
    ``sfm.reconstruct_static`` and its model is used."""
    import socialcam.sfm

    _pc, paths, names, times, raw, model = _scene(tmp_path, clips, 2)
    seen: dict[str, object] = {}

    def fake_detect(images, progress=False, **kw):
        seen["detect"] = [Path(p).name for p in images]
        at = {p.name: r for p, r in zip(paths, raw, strict=True)}
        return [at[Path(p).name] for p in images]

    def fake_sfm(image_dir, out_dir, **kw):
        """Checks the links and writes the model as the linked names, one camera folder."""
        seen["sfm"] = sorted(p.name for p in Path(image_dir).rglob("*.png"))
        seen["sfm_kw"] = kw
        subs = sorted(p.name for p in Path(image_dir).iterdir() if p.is_dir())
        seen["subs"] = subs
        if Path(out_dir).exists():  # overwrite=True, as the real one
            shutil.rmtree(out_dir)
        linked = Path(out_dir) / "model"
        linked.mkdir(parents=True)
        for f in ("cameras.txt", "points3D.txt"):
            (linked / f).write_text((model / f).read_text())
        lines = (model / "images.txt").read_text().splitlines(keepends=True)
        (linked / "images.txt").write_text("".join(
            " ".join([*ln.split(" ")[:-1], f"{subs[0]}/{ln.split(' ')[-1]}"]) if ln.strip() else ln
            for ln in lines))  # fmt: skip
        return linked

    monkeypatch.setattr(bodies, "detect_body_joints", fake_detect)
    monkeypatch.setattr(socialcam.sfm, "reconstruct_static", fake_sfm)
    (tmp_path / "work").mkdir()
    (tmp_path / "work" / "mine.txt").write_text("the user's")
    res = reconstruct_body_from_photos(paths, times=times, work_dir=tmp_path / "work")
    assert (tmp_path / "work" / "mine.txt").read_text() == "the user's"
    assert seen["sfm_kw"]["overwrite"] is True
    # a rerun replaces what the first made; a user's own folder of that name is refused
    again = reconstruct_body_from_photos(paths, times=times, work_dir=tmp_path / "work")
    np.testing.assert_array_equal(again.body.points, res.body.points)
    (tmp_path / "mine" / "images").mkdir(parents=True)
    (tmp_path / "mine" / "images" / "photo.jpg").write_text("a user's photo")
    with pytest.raises(ValueError, match="was not made by reconstruct_body_from_photos"):
        reconstruct_body_from_photos(paths, times=times, work_dir=tmp_path / "mine")
    assert (tmp_path / "mine" / "images" / "photo.jpg").read_text() == "a user's photo"
    assert seen["sfm"] == sorted(names) and seen["subs"] == ["camera000"]
    assert seen["sfm_kw"]["camera_mode"] == "per_image"
    assert seen["detect"] == [Path(p).name for p in res.photos]
    direct = reconstruct_body_from_photos(paths, times=times, model=model, joints=raw)
    np.testing.assert_allclose(res.body.points, direct.body.points, atol=1e-9)


def test_bad_input(tmp_path, clips):
    pc, paths, names, times, raw, model = _scene(tmp_path, clips, 4)
    run = reconstruct_body_from_photos
    with pytest.raises(ValueError, match=r"photos: .*not a file"):
        run([*paths, tmp_path / "nope.jpg"], model=model, joints=raw)
    other = tmp_path / "other"
    other.mkdir()
    Image.new("RGB", (8, 8)).save(other / names[0])
    with pytest.raises(ValueError, match="file names must be distinct"):
        run([*paths, other / names[0]], model=model)
    with pytest.raises(ValueError, match=f"{paths[0].name}' has no EXIF"):
        run(paths, model=model, joints=raw)
    with pytest.raises(ValueError, match="joints: expected"):
        run(paths, times=times, model=model, joints=raw[:-1])
    with pytest.raises(ValueError, match=r"joints\[0\]"):
        run(paths, times=times, model=model, joints=[r[..., :1] for r in raw])
    with pytest.raises(ValueError, match="no person was detected in any photo"):
        run(paths, times=times, model=model, joints=[r[:0] for r in raw])
    with pytest.raises(ValueError, match="work_dir"):
        run(paths, times=times, joints=raw)
    with pytest.raises(ValueError, match="camera_mode"):
        run(paths, times=times, model=model, joints=raw, camera_mode="auto")
    with pytest.raises(ValueError, match=r"model: .* is not a folder"):
        run(paths, times=times, model=tmp_path / "none", joints=raw)
    small = next(p for p in paths if p.name == names[0])
    Image.new("RGB", (640, 480)).save(small)
    with pytest.raises(ValueError, match=f"{names[0]}' is 640×480 pixels but its camera"):
        run(paths, times=times, model=model, joints=raw)
    out_of_model = [i for i, p in enumerate(paths) if p.name in names[len(pc.cameras) :]]
    with pytest.raises(ValueError, match="0 of 2 photos are registered"):
        run([paths[i] for i in out_of_model], times=times[out_of_model], model=model,
            joints=[raw[i] for i in out_of_model])  # fmt: skip
    # the command line names its flag
    out = tmp_path / "out"
    base = ["bodies", *map(str, paths), "--out", str(out), "--model", str(model)]
    (tmp_path / "short.csv").write_text(f"{names[0]},1.0\n")
    assert main([*base, "--times", str(tmp_path / "short.csv")]) == 2
    (tmp_path / "bad.csv").write_text(f"{names[0]},1.0\n{names[1]},soon\n")
    assert main([*base, "--times", str(tmp_path / "bad.csv")]) == 2
    assert main([*base, "--times", str(tmp_path / "times.csv"), "--joints", "x.npz"]) == 2
    assert not (out / "body.csv").exists()


def test_known_length_gives_metres(tmp_path, clips):
    """A model 2.5 times too small (as structure from motion may leave it) with the
    shoulders' median width given: the skeleton in metres, as with the metric model; in
    the model's units without it."""
    from socialcam.bodies import write_body

    pc, paths, names, times, raw, model = _scene(tmp_path, clips, 5, unit=2.5)
    F = len(pc.cameras)
    idx = [names[:F].index(Path(p).name) for p in paths if Path(p).name in names[:F]]
    truth = pc.points[idx]
    a, b = BODY_JOINTS.index("LeftShoulder"), BODY_JOINTS.index("RightShoulder")
    width = float(np.median(np.linalg.norm(truth[:, a] - truth[:, b], axis=-1)))
    direct = _direct(pc, idx)
    free = reconstruct_body_from_photos(paths, times=times, model=model, joints=raw)
    assert free.scale is None
    np.testing.assert_allclose(free.body.points * 2.5, direct, atol=1e-6)
    res = reconstruct_body_from_photos(
        paths, times=times, model=model, joints=raw,
        known_length=("LeftShoulder", "RightShoulder", width),
    )  # fmt: skip
    err = np.nanmedian(np.linalg.norm(res.body.points - truth, axis=-1))
    # the metric skeleton, scaled by the error of the reconstructed shoulders' median width
    # (measured -2.7 % to +3.5 % over seeds 0-9, +1.3 % on this one)
    np.testing.assert_allclose(res.body.points, direct * res.scale / 2.5, atol=1e-6)
    assert abs(res.scale / 2.5 - 1) < 0.04, res.scale
    assert err < 0.04, err
    np.testing.assert_allclose(res.cameras.C, pc.cameras.C[idx], rtol=0.03, atol=0.2)
    report = json.loads(
        (Path(write_body(res, tmp_path / "o", plots=False)) / "report.json").read_text()
    )
    assert report["units"] == "metres" and abs(report["metres_per_model_unit"] - res.scale) < 1e-9
    with pytest.raises(ValueError, match=r"^plots: expected a bool"):  # "no" drew them
        write_body(res, tmp_path / "p", plots="no")  # type: ignore[arg-type]
    for bad, msg in ((("Nose", "RightShoulder", 0.3), "'Nose' is not one of"),
                     (("Head", "Head", 0.3), "two different joints"),
                     (("Head", "LeftHip", -1.0), "known_length"),
                     (("Head", 0.3), "expected")):  # fmt: skip
        with pytest.raises(ValueError, match=msg):
            reconstruct_body_from_photos(paths, times=times, model=model, joints=raw,
                                         known_length=bad)  # fmt: skip
    base = ["bodies", *map(str, paths), "--out", str(tmp_path / "c"), "--model", str(model),
            "--times", str(tmp_path / "times.csv"), "--joints", str(tmp_path / "joints.npz")]  # fmt: skip
    assert main([*base, "--known-length", "LeftShoulder", "RightShoulder", "wide"]) == 2
    assert main([*base, "--known-length", "LeftShoulder", "RightShoulder", str(width)]) == 0


def test_per_folder_links_one_folder_per_photographer(tmp_path, monkeypatch):
    """``camera_mode="per_folder"``: the photos of each folder (e.g. one per photographer)
    are linked into a sub-folder of their own, so structure from motion gives each folder
    one camera."""
    import socialcam.sfm

    photos = []
    for who, n in (("anna", 2), ("ben", 3)):
        (tmp_path / who).mkdir()
        for i in range(n):
            Image.new("RGB", (32, 24)).save(tmp_path / who / f"{who}{i}.png")
            photos.append(tmp_path / who / f"{who}{i}.png")
    seen = {}

    class Stop(Exception):
        pass

    def fake_sfm(image_dir, out_dir, **kw):
        seen.update(kw)
        seen["layout"] = sorted(
            str(p.relative_to(image_dir)) for p in Path(image_dir).rglob("*.png")
        )
        raise Stop

    monkeypatch.setattr(socialcam.sfm, "reconstruct_static", fake_sfm)
    with pytest.raises(Stop):
        reconstruct_body_from_photos(photos, times=np.arange(5.0), work_dir=tmp_path / "w",
                                     camera_mode="per_folder")  # fmt: skip
    assert seen["camera_mode"] == "per_folder"
    assert seen["layout"] == ["camera000/anna0.png", "camera000/anna1.png", "camera001/ben0.png",
                              "camera001/ben1.png", "camera001/ben2.png"]  # fmt: skip


def test_real_structure_from_motion_on_real_photos(tmp_path, data_dir, clips):
    """The whole chain with ``sfm.reconstruct_static`` running for real on six real photos
    (the Sceaux castle) through the links it makes: a person standing before the castle (a
    CMU pose, scaled to the scene), its joints projected into the photos through a first
    reconstruction's cameras and lens (+ 0.5 px noise). The chain's own reconstruction
    (another run, its own frame and scale) must put the skeleton where those pixels say:
    its reprojection through its cameras and lens matches them (measured 0.41 px median; 11
    px with each photo paired with the next photo's camera), and its shape matches the
    person's up to a similarity (0.8 % of its height)."""
    import pycolmap

    from socialcam import align_similarity
    from socialcam.sfm import reconstruct_static

    photos = sorted((data_dir / "sceaux_castle_small").glob("*.jpg"))
    made = reconstruct_static(
        data_dir / "sceaux_castle_small", tmp_path / "first", max_image_size=800
    )
    first = pycolmap.Reconstruction(str(made))
    by_name = {img.name: img for img in first.images.values()}
    X = np.array([p.xyz for p in first.points3D.values()])
    C = np.array([by_name[p.name].projection_center() for p in photos])
    # the person: stands at the points' median, 1/4 of the cameras' distance to it tall
    centre = np.median(X, axis=0)
    pose = photo_collection(clips[0].positions, clips[0].names, clips[0].fps, seed=0).points[0]
    pose = pose - pose.mean(axis=0)
    size = 0.25 * np.median(np.linalg.norm(C - centre, axis=1)) / np.ptp(pose[:, 2])
    person = centre + size * pose
    rng = np.random.default_rng(0)
    raw = []
    for p in photos:
        img = by_name[p.name]
        cam = first.cameras[img.camera_id]
        pose_ = img.cam_from_world() if callable(img.cam_from_world) else img.cam_from_world
        xc = np.array([pose_ * x for x in person])
        uv = np.asarray(cam.img_from_cam(xc), float) - 0.5 + rng.normal(0, 0.5, (len(person), 2))
        raw.append(uv[None])
    import socialcam.sfm

    real = socialcam.sfm.reconstruct_static

    def smaller(image_dir, out_dir, **kw):  # the photos at 800 px, as above
        return real(image_dir, out_dir, max_image_size=800, **kw)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(socialcam.sfm, "reconstruct_static", smaller)
        res = reconstruct_body_from_photos(photos, times=np.arange(6.0), joints=raw,
                                           work_dir=tmp_path / "work", camera_mode="single")  # fmt: skip
    assert len(res.photos) == 6 and not res.skipped
    # reprojected through the chain's own cameras and lens: on the given raw pixels
    model = pycolmap.Reconstruction(res.model)
    second = {img.name: img for img in model.images.values()}
    resid = []
    for f, p in enumerate(res.photos):
        img = second[f"camera000/{Path(p).name}"]
        cam = model.cameras[img.camera_id]
        pose_ = img.cam_from_world() if callable(img.cam_from_world) else img.cam_from_world
        xc = np.array([pose_ * x for x in res.body.points[f]])
        uv = np.asarray(cam.img_from_cam(xc), float) - 0.5
        resid.append(np.linalg.norm(uv - raw[photos.index(Path(p))][0], axis=1))
    assert np.median(resid) < 1.5, np.median(resid)
    s, R, t = align_similarity(res.body.points[0], person)
    shape = np.linalg.norm(s * res.body.points[0] @ R.T + t - person, axis=1)
    assert np.median(shape) < 0.03 * np.ptp(person[:, 2]), (np.median(shape), np.ptp(person[:, 2]))


def _exif_photo(path, offset=None):
    """A small JPEG taken at 2024-05-01 10:00:00 (EXIF), with ``OffsetTimeOriginal``."""
    ex = Image.Exif()
    ifd = ex.get_ifd(0x8769)
    ifd[0x9003] = "2024:05:01 10:00:00"  # DateTimeOriginal
    if offset is not None:
        ifd[0x9011] = offset  # OffsetTimeOriginal
    Image.new("RGB", (16, 12)).save(path, exif=ex.tobytes())
    return path


def test_photo_times_bad_exif_offset(tmp_path):
    """``OffsetTimeOriginal`` is ``±HH:MM``; blank (spaces, and the colon, as EXIF writes an
    unknown offset) is read as absent; anything else is a ValueError naming the file, the
    tag and the value (it was a bare unpacking, int() or datetime error)."""
    ref = _exif_photo(tmp_path / "ref.jpg")
    east = _exif_photo(tmp_path / "east.jpg", "+02:30")
    np.testing.assert_allclose(bodies.photo_times([ref, east]), [9000.0, 0.0])
    for k, blank in enumerate(["      ", "   :  ", ""]):
        p = _exif_photo(tmp_path / f"blank{k}.jpg", blank)
        np.testing.assert_allclose(bodies.photo_times([ref, p]), [0.0, 0.0])
    for k, bad in enumerate(["+5", "Z", "+ab:cd", "+99:00", "+05:60", "05:00", "+05:00x"]):
        p = _exif_photo(tmp_path / f"bad{k}.jpg", bad)
        with pytest.raises(ValueError, match=rf"bad{k}\.jpg' has an unreadable OffsetTimeOriginal"):
            bodies.photo_times([ref, p])


def test_photo_times_bad_arguments(tmp_path):
    """``times`` that is not a sequence and photos that are not paths are ValueErrors naming
    the argument (not a TypeError from len() or an AttributeError from PIL)."""
    ref = _exif_photo(tmp_path / "ref.jpg")
    for bad in (1.0, "1.0", np.float64(1.0)):
        with pytest.raises(ValueError, match="times: expected a sequence"):
            bodies.photo_times([ref], times=bad)
    np.testing.assert_allclose(bodies.photo_times([ref, ref], times=np.array([1.0, 2.5])),
                               [0.0, 1.5])  # fmt: skip
    for photos in ([None], [ref, 3], [b"ref.jpg"]):
        with pytest.raises(ValueError, match=r"photos: photo \d is not a path"):
            bodies.photo_times(photos)
        with pytest.raises(ValueError, match=r"photos: photo \d is not a path"):
            bodies.photo_times(photos, times=[0.0] * len(photos))
    with pytest.raises(ValueError, match=r"photos: photo 0 is not a path"):
        reconstruct_body_from_photos([None], times=[0.0])
