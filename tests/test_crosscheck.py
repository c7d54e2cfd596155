"""verify/crosscheck and scenes/nerf_layout on a fake NeRF-path data set and log folder
(files written in the formats of jingweim/totems run.py)."""

from types import SimpleNamespace

import numpy as np
import pytest

from scenes import folder
from scenes.errors import BadInput
from scenes.photo.nerf_layout import read_nerf_case
from verify.report.crosscheck import (crosscheck, parse_loss_txt, read_nerf_log,
                                      write_crosscheck)

W, H, DS = 320, 240, 4
ROI = [8, 4, 304, 232]


@pytest.fixture
def nerf(tmp_path):
    rng = np.random.default_rng(0)
    data = tmp_path / "data-compiled"
    case = data / "color-patch" / "IMG_000"
    K = np.array([[300.0, 0, 159.5], [0, 300.0, 119.5], [0, 0, 1]])
    folder.write_calib(data / "calib.npy", K, dist=np.zeros(5), roi=ROI)
    photo = rng.random((H, W, 3)).astype(np.float32)
    folder.write_image(case / "image.png", photo)
    masks = np.zeros((2, H, W), bool)
    masks[0, 180:210, 40:70] = True
    masks[1, 180:210, 240:270] = True
    for j, m in enumerate(masks):
        folder.write_image(case / "totem_masks" / f"totem_{j:03d}.png", m)
    initial = np.array([[-0.5, 0.4, 2.0], [0.6, 0.4, 2.1]])
    folder.write_npy(case / "initial_totem_pose.npy", initial)

    log = tmp_path / "logs" / "exp"
    learned = (initial + [[0.01, 0.0, 0.0], [0.0, -0.02, 0.0]]).astype(np.float32)
    lines = []
    for it in (100, 200):                      # run.py: one loss line, one line per totem
        pos = learned if it == 200 else initial.astype(np.float32)
        lines.append(f"[TRAIN] Iter: {it} Loss: 0.01 MSE:0.001 IoU: 0.2  PSNR: 30.0\n")
        lines += [f"[TRAIN] Iter: {it} Totem{n + 1}: {pos[n]}\n" for n in range(2)]
    lines.append("[TRAIN] Iter: 300 Totem1: [ 9. 9. 9.]\n")      # a cut-off last report
    (log).mkdir(parents=True)
    (log / "loss.txt").write_text("".join(lines))
    (log / "args.txt").write_text("ior_totem = 1.52\ntotem_radius = 0.1\n")
    h, w = H // DS, W // DS
    recon = np.full((H, W, 3), 0.4, np.float32)
    cam = np.full((h, w, 3), 0.5, np.float32)                    # ours + 0.1 everywhere
    folder.write_image(log / "render_050000" / "camera_view.png", cam)
    folder.write_image(log / "render_010000" / "camera_view.png", cam * 0)   # older
    protect = np.zeros((h, w), bool)
    protect[10:40, 10:70] = True
    x, y, cw, ch = (np.round(np.array(ROI) / DS)).astype(int)
    det = log / "detect_050000"
    folder.write_image(det / "intermediate" / "protect_mask.png", protect[y:y + ch, x:x + cw])
    heat = rng.random((30, 30))
    folder.write_npy(det / "results" / "L1" / "heatmap.npy", heat)
    ours = SimpleNamespace(centers=initial, recon=recon)
    return case, log, ours, heat, learned


def test_parse_loss_txt_takes_last_complete_report():
    text = ("[TRAIN] Iter: 100 Totem1: [ 0.1 -0.2  3. ]\n"
            "[TRAIN] Iter: 100 Totem2: [1.5e-01 2.0e+00 3.1e+00]\n"
            "[TRAIN] Iter: 200 Totem2: [0. 0. 0.]\n")
    c, it = parse_loss_txt(text)
    assert it == 100 and np.allclose(c, [[0.1, -0.2, 3.0], [0.15, 2.0, 3.1]])


def test_read_case_and_crosscheck(nerf, tmp_path):
    case, log, ours, heat, learned = nerf
    scene = read_nerf_case(case)
    assert scene.n_totems == 2 and np.allclose(scene.radius, 0.1)
    assert np.allclose(scene.ior, 1.52) and scene.initial_pose.shape == (2, 3)
    run = read_nerf_log(log)
    assert np.allclose(run.centers, learned) and run.centers_iter == 200
    assert run.camera_view.max() > 0.4 and run.protect_cropped

    protect = np.zeros((H, W), bool)
    protect[:, : W // 2] = True                                # ours: left half
    res = crosscheck(scene, ours, heat * 2 + 1, protect, run)
    assert [t["distance_m"] for t in res["totems"]] == pytest.approx([0.01, 0.02], abs=1e-6)
    r = res["recon"]
    assert r["L1_ours_vs_nerf"] == pytest.approx(0.1, abs=0.005)
    # compared pixels: NeRF's protect (placed back with roi) within our left half
    assert r["pixels_compared"] == 30 * (W // DS // 2 - 10)
    assert res["heatmap"]["pearson"] == pytest.approx(1.0)
    assert res["heatmap"]["top_iou"] == 1.0

    shuffled = np.random.default_rng(1).permutation(heat.ravel()).reshape(30, 30)
    res2 = crosscheck(scene, ours, shuffled, protect, run)
    assert abs(res2["heatmap"]["pearson"]) < 0.2 and res2["heatmap"]["top_iou"] < 0.5
    assert res2["heatmap"]["only_ours"]

    import matplotlib
    backend = matplotlib.get_backend()
    matplotlib.use("svg")                     # any backend the caller chose (a notebook's)
    try:
        out = write_crosscheck(res, tmp_path / "cc")
        assert matplotlib.get_backend() == "svg"           # is left as it was
    finally:
        matplotlib.use(backend)
    import json
    rep = json.loads((out / "report.json").read_text())
    assert rep["totems"][1]["nerf"] == pytest.approx(learned[1].tolist())
    assert folder.read_image(out / "crosscheck.png").shape[2] == 3


def test_not_a_nerf_log(tmp_path):
    (tmp_path / "x").mkdir()
    with pytest.raises(BadInput, match="not a NeRF-path run"):
        read_nerf_log(tmp_path / "x")
    with pytest.raises(BadInput, match="photo not found"):
        read_nerf_case(tmp_path / "x")
