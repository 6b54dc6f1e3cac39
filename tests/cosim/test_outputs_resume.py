"""On resume the CSV rows and PVD frames kept are decided on times read back from the files,
i.e. rounded to 10 significant digits: the row of the resume instant must be recognised
whichever way its time was rounded (a killed direct shear run once lost it)."""
import pytest

from cosim.outputs import CsvSeries, PvdCollection, kept_on_resume


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
