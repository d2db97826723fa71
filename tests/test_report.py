"""The self-contained HTML report and the diagnostic plots (estimators.diagnostics.report / plots)."""

from __future__ import annotations

import base64
import os
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from estimators.diagnostics.plots import (
    plot_before_after,
    plot_correlations,
    plot_overlay,
    plot_ranking,
    plot_residuals,
    plot_spectrum,
)
from estimators.diagnostics.report import HtmlReport, write_bytes_atomic
from estimators.diagnostics.residuals import ResidualAnalysis, analyse_residuals
from spaceid_gym.errors import SpaceIdInputError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def case() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, ResidualAnalysis]:
    """20 s at 50 Hz, 3 channels, 2 joints; joint 2 moves in [8, 12] s where channel 1 has a bump."""
    rng = np.random.default_rng(0)
    t = np.arange(1001) * 0.02
    dq = np.zeros((t.size, 2))
    dq[:, 0] = 0.2 * np.sin(2 * np.pi * 0.05 * t)
    moving = (t >= 8.0) & (t <= 12.0)
    dq[moving, 1] = 0.3 * np.sin(np.pi * (t[moving] - 8.0) / 4.0)
    q = np.cumsum(dq, axis=0) * 0.02
    predicted = np.column_stack([np.sin(0.3 * t), np.cos(0.2 * t), 0.1 * t])
    measured = predicted + rng.normal(0.0, 0.01, predicted.shape)
    measured[moving, 0] += 0.05 * np.sin(np.pi * (t[moving] - 8.0) / 4.0)
    return t, q, dq, measured, predicted, analyse_residuals(t, measured, predicted, q, dq)


def decoded_images(page: str) -> list[bytes]:
    return [base64.b64decode(m) for m in re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)]


def test_report_escapes_text_and_embeds_images(tmp_path: Path) -> None:
    png = tmp_path / "a.png"
    plot_before_after(png, ["wx", "wy"], [2.0, 1.5], [1.0, 1.0], "RMS / noise")
    report = HtmlReport("Run <1> & co")
    report.add_heading("<script>alert('x')</script>")
    report.add_paragraph('residual "large" & structured <b>')
    report.add_table([{"effect": "<fuel>", "score": 1.23456789, "ok": True}, {"effect": "bias", "extra": None}], caption="a<b")
    report.add_table([[1, 2.5], ["x&y", np.float64(3.0)]], header=["n", "<v>"])
    report.add_image(png, caption="bars <1>")
    report.add_image(png.read_bytes(), caption="same, from bytes", alt='alt "quoted"')
    report.add_preformatted("spaceid diagnose --log <run1>")
    out = report.write(tmp_path / "sub" / "report.html")
    page = out.read_text(encoding="utf-8")
    assert "<script>" not in page and "&lt;script&gt;alert(&#x27;x&#x27;)&lt;/script&gt;" in page
    assert "<title>Run &lt;1&gt; &amp; co</title>" in page and "&lt;b&gt;" in page and "<b>" not in page
    assert "&lt;fuel&gt;" in page and ">1.235<" in page and ">yes<" in page and "x&amp;y" in page and "&lt;v&gt;" in page
    assert "<caption>a&lt;b</caption>" in page and "bars &lt;1&gt;" in page and 'alt="alt &quot;quoted&quot;"' in page
    images = decoded_images(page)
    assert len(images) == 2 and images[0] == images[1] == png.read_bytes()
    # self-contained: no external resource, no script
    assert not re.search(r'(src|href)="(?!data:)', page) and "<script" not in page


def test_report_rejects_bad_input(tmp_path: Path) -> None:
    report = HtmlReport("r")
    with pytest.raises(SpaceIdInputError, match="no such image"):
        report.add_image(tmp_path / "missing.png")
    (tmp_path / "fake.png").write_text("not a png")
    with pytest.raises(SpaceIdInputError, match="PNG"):
        report.add_image(tmp_path / "fake.png")
    with pytest.raises(SpaceIdInputError, match="row 1 has 1 cells"):
        report.add_table([[1, 2], [3]], header=["a", "b"])
    with pytest.raises(SpaceIdInputError, match="list of dicts"):
        report.add_table([[1, 2]])


def test_failed_write_leaves_no_partial_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    report = HtmlReport("r")
    report.add_paragraph("new")
    target = tmp_path / "report.html"

    def failing_replace(src: str, dst: str) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(OSError, match="disk full"):
        report.write(target)
    assert list(tmp_path.iterdir()) == []
    target.write_text("old content")
    with pytest.raises(OSError, match="disk full"):
        write_bytes_atomic(target, b"new content")
    assert target.read_text() == "old content" and list(tmp_path.iterdir()) == [target]
    monkeypatch.undo()
    assert write_bytes_atomic(target, b"new content").read_bytes() == b"new content"
    assert list(tmp_path.iterdir()) == [target]
    with pytest.raises(SpaceIdInputError, match="cannot write"):
        write_bytes_atomic(target / "inside_a_file.html", b"x")


def test_plots_write_pngs_and_full_report(tmp_path: Path, case: tuple) -> None:
    t, _, _, measured, predicted, analysis = case
    assert analysis.segments and (analysis.segments[0].t_start_s, analysis.segments[0].t_end_s) == (8.0, 12.0)
    residual = measured - predicted
    paths = [
        plot_overlay(
            tmp_path / "overlay.png", t, measured, predicted, analysis.segments, predicted_after=predicted, title="m vs p"
        ),
        plot_residuals(
            tmp_path / "residuals.png", t, residual, analysis.noise_std, analysis.segments, residual_after=residual / 2
        ),
        plot_correlations(tmp_path / "correlations.png", analysis),
        plot_spectrum(tmp_path / "spectrum.png", t, residual, dominant=analysis.dominant_frequencies, noise_std=0.01),
        plot_ranking(
            tmp_path / "ranking.png",
            [{"effect": "gyro bias", "delta BIC": "-12.5"}, {"effect": "payload", "delta BIC": "3.0"}],
            score_key="delta BIC",
            higher_is_better=False,
        ),
        plot_before_after(
            tmp_path / "before_after.png", analysis.channel_names, analysis.rms_over_noise, [1.0, 1.0, 1.0], "RMS / noise"
        ),
    ]
    for path in paths:
        assert path.read_bytes().startswith(PNG_SIGNATURE)
        height, width = imread(path).shape[:2]
        assert width >= 500 and height >= 200
    report = HtmlReport("Diagnosis")
    report.add_paragraph(analysis.structure_description())
    report.add_table(analysis.channel_rows(), caption="channels")
    report.add_table(analysis.segment_rows(), caption="where it fails")
    for path in paths:
        report.add_image(path, caption=path.stem)
    page = report.write(tmp_path / "report.html").read_text(encoding="utf-8")
    assert [image for image in decoded_images(page)] == [path.read_bytes() for path in paths]
    assert "8.00-12.00 s" in page and "q2" in page


def test_overlay_draws_the_failing_segments(tmp_path: Path, case: tuple) -> None:
    t, _, _, measured, predicted, analysis = case
    with_segments = imread(plot_overlay(tmp_path / "a.png", t, measured, predicted, analysis.segments))
    without = imread(plot_overlay(tmp_path / "b.png", t, measured, predicted, ()))
    below_legend = slice(int(0.1 * with_segments.shape[0]), None)
    differs = np.any(np.abs(with_segments[below_legend] - without[below_legend]) > 0.05, axis=-1)
    columns = np.flatnonzero(differs.any(axis=0))
    # the shaded band spans the segment's 4 s of the ~21 s axis (~ 1/5 of the plot width), nothing else changes
    assert 0.12 * with_segments.shape[1] < columns.size < 0.25 * with_segments.shape[1]
    assert columns.max() - columns.min() + 1 == columns.size  # one contiguous band


def test_plots_reject_bad_input(tmp_path: Path, case: tuple) -> None:
    t, _, _, measured, predicted, _ = case
    with pytest.raises(SpaceIdInputError, match="predicted"):
        plot_overlay(tmp_path / "x.png", t, measured, predicted[:, :2])
    with pytest.raises(SpaceIdInputError, match="channel names"):
        plot_overlay(tmp_path / "x.png", t, measured, predicted, channel_names=["a"])
    with pytest.raises(SpaceIdInputError, match="noise_std"):
        plot_residuals(tmp_path / "x.png", t, measured - predicted, [1.0, 2.0])
    with pytest.raises(SpaceIdInputError, match="'effect' and 'bic_improvement'"):
        plot_ranking(tmp_path / "x.png", [{"name": "bias", "bic_improvement": 1.0}])
    with pytest.raises(SpaceIdInputError, match="must be a number"):
        plot_ranking(tmp_path / "x.png", [{"effect": "bias", "bic_improvement": "large"}])
    with pytest.raises(SpaceIdInputError, match="one value before and after"):
        plot_before_after(tmp_path / "x.png", ["a", "b"], [1.0], [1.0, 2.0], "y")
    assert not (tmp_path / "x.png").exists()
