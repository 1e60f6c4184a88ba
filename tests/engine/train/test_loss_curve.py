import numpy as np
import cv2

from lirm.engine.train.loss_curve import read_metrics, write_loss_curves


def test_loss_curves_are_drawn_from_metrics_csv(tmp_path):
    csv_path = tmp_path / "metrics.csv"
    rows = ["step,loss,colour,lr"] + [f"{s},{2.0 * np.exp(-s / 30):.5f},{0.1 + 0.01 * (s % 3)},1e-3" for s in range(1, 101)]
    csv_path.write_text("\n".join(rows) + "\n")
    metrics = read_metrics(csv_path)
    assert metrics["step"][-1] == 100 and metrics["loss"][0] > metrics["loss"][-1]
    png = write_loss_curves(csv_path, tmp_path / "curves.png", columns=["loss", "colour"])
    image = cv2.imread(str(png))[..., ::-1]
    assert image.shape == (500, 900, 3)
    # The loss curve's colour (orange-red) is drawn, and falls from left to right (up the image = higher).
    red = (image[..., 0] > 150) & (image[..., 1] < 120) & (image[..., 2] < 80)
    ys, xs = np.nonzero(red[40:460, 70:880])
    assert len(xs) > 200
    assert ys[xs < 100].mean() < ys[xs > 700].mean()


def test_no_curves_for_an_empty_run(tmp_path):
    (tmp_path / "metrics.csv").write_text("step,loss\n")
    assert write_loss_curves(tmp_path / "metrics.csv", tmp_path / "c.png") is None
