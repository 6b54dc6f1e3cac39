"""On resume the CSV rows and PVD frames kept are decided on times read back from the files,
i.e. rounded to 10 significant digits: the row of the resume instant must be recognised
whichever way its time was rounded (a killed direct shear run once lost it). A checkpoint of
several files becomes current all at once: a kill among its renames is completed on resume
(a killed footing run once left a DEM checkpoint one row ahead of its loop state)."""
import json

import pytest

from cosim.outputs import (
    CHECKPOINT_COMMIT,
    CsvSeries,
    PvdCollection,
    commit_checkpoint,
    finish_commit,
    kept_on_resume,
    resume_row_missing,
    staged,
)


@pytest.mark.parametrize("rounded", [0.02165533079, 0.02165533080])  # t = 0.021655330795 rounded down / up
def test_the_row_of_the_resume_instant_is_kept_or_dropped_whichever_way_it_was_rounded(rounded):
    t = 0.021655330795
    assert kept_on_resume(rounded, t, keep_resume_instant=True)
    assert not kept_on_resume(rounded, t, keep_resume_instant=False)
    assert kept_on_resume(0.0216, t, keep_resume_instant=False)        # an earlier row always
    assert not kept_on_resume(0.0217, t, keep_resume_instant=True)     # a later one never


def test_series_and_collection_keep_what_precedes_the_resume_instant(tmp_path):
    series = CsvSeries(tmp_path / "s.csv", ["time", "x"])
    for k in range(4):
        series.append([k * 0.1 + 1e-13, float(k)])
    series.close()
    frames = PvdCollection(tmp_path / "p.pvd")
    for k in range(4):
        frames.add(k * 0.1, [tmp_path / f"f{k}.vtu"])
    resumed = CsvSeries(tmp_path / "s.csv", ["time", "x"], resume_time=0.2, keep_resume_instant=False)
    resumed.close()
    assert (tmp_path / "s.csv").read_text().splitlines()[1:] == ["1e-13,0", "0.1,1"]
    assert len(PvdCollection(tmp_path / "p.pvd", resume_time=0.2).entries) == 3


@pytest.mark.parametrize("output_instant", [True, False])
def test_the_row_of_the_resume_instant_comes_from_the_file_not_from_the_loaded_state(tmp_path, output_instant):
    """A run resumed on an output instant keeps the row the file has (computed again from a
    checkpoint of another rank count it read "no contacts": ratio 1, coordination 0) and writes
    it only if the file lacks it; off the output grid the file's final row is dropped."""
    series = CsvSeries(tmp_path / "s.csv", ["time", "x"])
    for k in range(3):
        series.append([k * 0.1, float(k)])
    series.close()
    resumed = CsvSeries(tmp_path / "s.csv", ["time", "x"], resume_time=0.2, keep_resume_instant=output_instant)
    resumed.close()
    assert resumed.resume_row_kept == output_instant
    assert not resume_row_missing(resumed, output_instant)
    assert len((tmp_path / "s.csv").read_text().splitlines()) == (4 if output_instant else 3)
    lacking = CsvSeries(tmp_path / "s.csv", ["time", "x"], resume_time=0.25, keep_resume_instant=output_instant)
    lacking.close()  # an instant the file has no row of (output.interval changed on --resume)
    assert not lacking.resume_row_kept and resume_row_missing(lacking, output_instant) == output_instant


def test_a_checkpoint_of_several_files_is_committed_whole(tmp_path):
    for name, text in (("checkpoint.npz", "dem 1"), ("state.json", "row 1")):
        (tmp_path / name).write_text(text)
    for name, text in (("checkpoint.npz", "dem 2"), ("state.json", "row 2")):
        staged(tmp_path / name).write_text(text)
    commit_checkpoint(tmp_path, [tmp_path / "checkpoint.npz", tmp_path / "state.json"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["checkpoint.npz", "state.json"]
    assert (tmp_path / "checkpoint.npz").read_text() == "dem 2" and (tmp_path / "state.json").read_text() == "row 2"


def test_a_commit_killed_among_its_renames_is_finished_on_resume(tmp_path):
    """Killed after the DEM file was renamed and before the state was: the record is left, and
    finish_commit renames the rest, so that both files are of the new instant."""
    (tmp_path / "checkpoint.npz").write_text("dem 2")          # renamed before the kill
    (tmp_path / "state.json").write_text("row 1")              # not yet
    staged(tmp_path / "state.json").write_text("row 2")
    (tmp_path / CHECKPOINT_COMMIT).write_text(json.dumps(["checkpoint.npz", "state.json"]))
    finish_commit(tmp_path)
    assert (tmp_path / "state.json").read_text() == "row 2"
    assert not (tmp_path / CHECKPOINT_COMMIT).exists() and not staged(tmp_path / "state.json").exists()
    finish_commit(tmp_path)  # no record: nothing to do


def test_resume_finishes_a_commit_left_in_a_model_folder(tmp_path):
    """The footing and embedded kinds checkpoint into <out>/<model>/: --resume finishes a commit
    record left there too (cosim.cli), not only one in the output folder."""
    from cosim.cli import _finish_interrupted_commit
    model = tmp_path / "coupled"
    model.mkdir()
    (model / "checkpoint.npz").write_text("dem 2")
    staged(model / "checkpoint.fe.rank0of1.npz").write_text("fe 2")
    (model / CHECKPOINT_COMMIT).write_text(json.dumps(["checkpoint.npz", "checkpoint.fe.rank0of1.npz"]))
    _finish_interrupted_commit(tmp_path)
    assert (model / "checkpoint.fe.rank0of1.npz").read_text() == "fe 2"
    assert not (model / CHECKPOINT_COMMIT).exists()


def test_staged_files_of_a_checkpoint_killed_while_being_written_are_ignored(tmp_path):
    """Killed before the commit record: the current files stay the previous instant's."""
    (tmp_path / "state.json").write_text("row 1")
    staged(tmp_path / "state.json").write_text("row 2, half writt")
    finish_commit(tmp_path)
    assert (tmp_path / "state.json").read_text() == "row 1"
