"""Figures fit for a paper: every command that draws takes `--format {png,pdf,svg}` and `--dpi N`, writes its figures
with the asked suffix in that format (no stray PNG), and refuses a bad value with one line naming the option; the one
helper that writes a figure, `robotadapt.report.output.save_figure`, writes it whole or not at all."""

from __future__ import annotations

import base64
import struct
from pathlib import Path

import matplotlib.pyplot as plt
import pytest
import tomli_w

from robotadapt.cli import main
from robotadapt.report.html import GalleryEntry, gallery_html
from robotadapt.report.output import DEFAULT_DPI, FigureFormat, save_figure
from robotadapt.validation import ConfigError
from test_cli import one_error_line
from test_report import elements

SHORT = ["example-6.3.1", "--t-final", "0.2"]
RUN_FIGURES = ("tracking_error", "parameters", "torques")


def file_format(path: Path) -> str:
    """'png', 'pdf' or 'svg' from the file's first bytes (its magic number), not from its name."""
    head = path.read_bytes()[:256]
    if head.startswith(b"\x89PNG\r\n\x1a\n"):
        return "png"
    if head.startswith(b"%PDF"):
        return "pdf"
    if head.lstrip().startswith((b"<?xml", b"<svg")) and b"<svg" in path.read_bytes()[:2000]:
        return "svg"
    return "unknown"


def png_width(path: Path) -> int:
    """Pixel width from the PNG's IHDR chunk (bytes 16-20, big-endian)."""
    return int(struct.unpack(">I", path.read_bytes()[16:20])[0])


def written(folder: Path, stems: tuple[str, ...] | list[str], fmt: str) -> None:
    """Each figure `stem.fmt` exists and really is `fmt`; no figure in another format (no stray .png) in `folder`."""
    for stem in stems:
        assert file_format(folder / f"{stem}.{fmt}") == fmt, stem
    others = {p.name for p in folder.rglob("*") if p.suffix in (".png", ".pdf", ".svg") and p.suffix != f".{fmt}"}
    assert others == set()


# ---------------------------------------------------------------------------------------------------------------------
# each command that draws


@pytest.mark.parametrize("fmt", ["pdf", "svg"])
def test_run_writes_its_three_figures_in_the_asked_format(tmp_path, capsys, fmt):
    assert main(["run", *SHORT, "--format", fmt, "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    written(tmp_path, RUN_FIGURES, fmt)


def test_the_png_width_scales_with_dpi(tmp_path, capsys):
    for dpi in (50, 100):
        assert main(["run", *SHORT, "--dpi", str(dpi), "--out", str(tmp_path / str(dpi))]) == 0
    capsys.readouterr()
    for stem in RUN_FIGURES:
        low, high = png_width(tmp_path / "50" / f"{stem}.png"), png_width(tmp_path / "100" / f"{stem}.png")
        assert high == pytest.approx(2 * low, abs=2), stem
    assert png_width(tmp_path / "100" / "torques.png") == pytest.approx(700, abs=2)  # figsize 7 in wide


def test_run_writes_the_study_overlays_in_the_asked_format(tmp_path, capsys):
    scenario = tmp_path / "s.toml"
    scenario.write_text(tomli_w.dumps({
        "robot": {"kind": "one_link"}, "plant": {"phi": [1.0, 1.0]}, "trajectory": {"kind": "sinusoid"},
        "controller": {"kind": "slotine_li", "Lam": 5.0, "Kv": 10.0, "Gamma": 10.0}, "simulation": {"t_final": 0.2},
        "study": {"controller.Kv": [5.0, 20.0]}}))
    assert main(["run", str(scenario), "--format", "svg", "--out", str(tmp_path / "out")]) == 0
    capsys.readouterr()
    written(tmp_path / "out", [*RUN_FIGURES, "study_controller_Kv"], "svg")


def test_run_on_mujoco_writes_the_options_figure_in_the_asked_format(tmp_path, capsys):
    pytest.importorskip("mujoco")
    assert main(["run", *SHORT, "--set", "plant.engine=mujoco", "--set", "robot.friction_terms=true", "--set",
                 "plant.damping=0.5", "--set", "plant.phi=[0.8,2.3,0.5,0.5]", "--set", "controller.phi_hat0=0",
                 "--format", "pdf", "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    written(tmp_path, [*RUN_FIGURES, "mujoco_options"], "pdf")


def test_the_gallery_links_its_pdf_figures(tmp_path, capsys, monkeypatch):
    """A browser shows no pdf in an <img>: the gallery links each one, with the right suffix."""
    monkeypatch.setattr("robotadapt.report.html.book_scenarios", lambda: ["example-6.3.1", "example-6.2.2"])
    assert main(["figures", "--t-final", "0.05", "--format", "pdf", "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    page = (tmp_path / "index.html").read_text(encoding="utf-8")
    links = [a["href"] for a in elements(page)["a"] if not a["href"].startswith("#")]
    assert links == [f"{name}/{stem}.pdf" for name in ("example-6.3.1", "example-6.2.2") for stem in RUN_FIGURES]
    assert "<img" not in page
    for link in links:
        assert file_format(tmp_path / link) == "pdf"
    written(tmp_path, [], "pdf")


def test_the_gallery_shows_svg_figures_as_images():
    entry = GalleryEntry("example-6.3.1", "two-link arm", "", {}, {"status": "ok"}, 1.0, 1.0, 0.1)
    images = [img["src"] for img in elements(gallery_html([entry], FigureFormat("svg")))["img"]]
    assert images == [f"example-6.3.1/{stem}.svg" for stem in RUN_FIGURES]


@pytest.mark.parametrize("fmt, embedded", [("svg", "image/svg+xml"), ("pdf", "image/png")])
def test_compare_writes_its_figures_in_the_asked_format_and_embeds_them(tmp_path, capsys, fmt, embedded):
    """report.html stays self-contained: the svg files themselves as data URIs; for pdf, PNGs drawn at the same dpi."""
    assert main(["compare", *SHORT, "--controllers", "slotine_li,pd", "--format", fmt, "--dpi", "60",
                 "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    stems = ("errors", "parameter_errors", "torques", "laws")
    written(tmp_path, stems, fmt)
    images = [img["src"] for img in elements((tmp_path / "report.html").read_text(encoding="utf-8"))["img"]]
    assert len(images) == 4 and all(src.startswith(f"data:{embedded};base64,") for src in images)
    decoded = [base64.b64decode(src.split(",", 1)[1]) for src in images]
    if fmt == "svg":
        assert decoded == [(tmp_path / f"{stem}.svg").read_bytes() for stem in stems]
    else:
        assert all(struct.unpack(">I", png[16:20])[0] < 800 for png in decoded)  # 60 dpi, not the default


def test_sweep_writes_its_figure_in_the_asked_format(tmp_path, capsys):
    out = tmp_path / "sw"
    assert main(["sweep", *SHORT, "--grid", "controller.Kv=5,10", "--workers", "1", "--format", "pdf",
                 "--out", str(out)]) == 0
    capsys.readouterr()
    assert {p.name for p in out.iterdir()} == {"runs.jsonl", "sweep.json", "sweep.pdf"}
    written(out, ["sweep"], "pdf")


def test_tune_writes_its_figure_in_the_asked_format(tmp_path, capsys):
    pytest.importorskip("jax")
    assert main(["tune", *SHORT, "--backend", "jax", "--vary", "controller.Kv=2:50", "--max-runs", "2", "--surface", "0",
                 "--format", "svg", "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    written(tmp_path, ["tune"], "svg")


def test_pe_writes_its_figure_in_the_asked_format(tmp_path, capsys):
    assert main(["pe", "example-6.5.2a", "--format", "svg", "--out", str(tmp_path)]) == 0
    assert "wrote" in capsys.readouterr().out
    written(tmp_path, ["pe"], "svg")


# ---------------------------------------------------------------------------------------------------------------------
# bad values: one line naming the option, exit 2, before any run


COMMANDS = {"run": ["run", *SHORT], "figures": ["figures", "--t-final", "0.05"], "compare": ["compare", *SHORT],
            "sweep": ["sweep", *SHORT, "--grid", "controller.Kv=5,10", "--workers", "1"],
            "tune": ["tune", *SHORT, "--vary", "controller.Kv=2:50"], "pe": ["pe", "example-6.5.2a"]}


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize("bad, option", [(["--format", "bmp"], "--format"), (["--dpi", "0"], "--dpi"),
                                         (["--dpi", "-3"], "--dpi"), (["--dpi", "300.5"], "--dpi")])
def test_a_bad_format_or_dpi_is_one_line_naming_the_option(tmp_path, capsys, command, bad, option):
    out = tmp_path / "out"
    assert main([*COMMANDS[command], *bad, "--out", str(out)]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert line.startswith(f"robotadapt: error: {option}: ")
    assert not out.exists()  # refused before running anything


# ---------------------------------------------------------------------------------------------------------------------
# the helper


def test_figure_format_names_files_and_refuses_bad_values():
    assert FigureFormat().format == "png" and FigureFormat().dpi == DEFAULT_DPI
    assert FigureFormat("pdf", 300).name("torques") == "torques.pdf"
    assert FigureFormat("svg").suffix == ".svg"
    for bad, field in ((("jpg", 100), "--format"), (("png", 0), "--dpi"), (("png", True), "--dpi")):
        with pytest.raises(ConfigError, match=f"^{field}: "):
            FigureFormat(*bad)


def test_save_figure_writes_the_format_asked_and_closes_the_figure(tmp_path):
    fig, ax = plt.subplots(figsize=(2, 1))
    ax.plot([0, 1], [0, 1])
    path = save_figure(fig, tmp_path / "f.png", FigureFormat("png", 80))
    assert file_format(path) == "png" and png_width(path) == 160
    assert not plt.fignum_exists(fig.number)


def test_save_figure_leaves_no_partial_file_when_drawing_fails(tmp_path, monkeypatch):
    """Whole or not at all: the old file stays as it was, no temporary file is left, the figure is closed anyway."""
    path = tmp_path / "f.svg"
    path.write_text("old")
    fig, _ = plt.subplots()

    def broken(target, **kwargs):
        target.write(b"<?xml half")
        raise RuntimeError("drawing failed")

    monkeypatch.setattr(fig, "savefig", broken)
    with pytest.raises(RuntimeError, match="drawing failed"):
        save_figure(fig, path, FigureFormat("svg"))
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["f.svg"]
    assert not plt.fignum_exists(fig.number)
