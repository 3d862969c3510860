import pytest

from carapost.core.document import Document
from carapost.core.errors import CaraError
from carapost.core.labels import merge_labels, parse_label_text, read_label_file
from carapost.io import cara
from carapost.io.imports import import_labels_from_cara, import_labels_from_text
from support import make_project


def test_parse_several_per_line_and_blank_lines():
    assert parse_label_text("Mouth_L_Corner Mouth_R_Corner\n\n  Chin_Center\tNose_Tip\n") == [
        "Mouth_L_Corner", "Mouth_R_Corner", "Chin_Center", "Nose_Tip"]


def test_guide_example(tmp_path):
    f = tmp_path / "labels.txt"
    f.write_text("Mouth_L_Corner\nMouth_R_Corner\nChin_Center\nChin_L_Pt1\nChin_L_Pt2\nChin_R_Pt1\nChin_R_Pt2\nNose_Tip\n")
    assert len(read_label_file(f)) == 8


def test_duplicates_get_copy_appended():
    assert merge_labels(["A", "B"], ["B", "C", "A", "B"]) == ["A", "B", "B - Copy", "C", "A - Copy", "B - Copy - Copy"]


def test_import_text_adds_and_undoes(tmp_path, project):
    f = tmp_path / "l.txt"
    f.write_text("M0 Nose_Tip\nChin")
    doc = Document(project)
    old = list(project.labels)
    doc.run(import_labels_from_text(project, f))
    assert project.labels == old + ["M0 - Copy", "Nose_Tip", "Chin"]
    doc.undo()
    assert project.labels == old


def test_import_from_cara(tmp_path, project):
    other = make_project(frames=3, points=4)
    other.labels = ["Brow_L", "Brow_R"]
    other.points[1].label = "Jaw"
    cara.save_project(other, tmp_path / "rom.cara")
    project.labels = ["Brow_L"]
    Document(project).run(import_labels_from_cara(project, tmp_path / "rom.cara"))
    assert project.labels == ["Brow_L", "Brow_L - Copy", "Brow_R", "M0", "Jaw", "M2"]


def test_bad_label_files(tmp_path):
    with pytest.raises(CaraError, match="no such file"):
        read_label_file(tmp_path / "missing.txt")
    b = tmp_path / "bin.txt"
    b.write_bytes(b"\0\1\2")
    with pytest.raises(CaraError, match="bin.txt"):
        read_label_file(b)
