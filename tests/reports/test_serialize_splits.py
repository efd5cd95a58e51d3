"""A split by sampling time keeps its sensor columns in results.json (reports.serialize)."""
import json

from identification import DetectionResult, DetectSettings
from identification.studies.splits import Split, time_window_split
from reports.serialize import detection_dict, dumps, split_dict

PAIRS = [("cA", 0.5), ("cB", 0.5), ("cA", 1.0), ("cB", 1.0), ("cA", 2.0), ("cB", 2.0)]


def test_a_time_split_round_trips_through_results_json_with_its_sensor_columns():
    sp = time_window_split(PAIRS, 3, (0.5, 1.0), (2.0, 2.0), inputs=[0, 2], series=[1])
    assert (sp.cal_sensors, sp.val_sensors) == ((0, 1, 2, 3), (4, 5))
    by_exp = Split("exp", [0], [1, 2])
    det = DetectionResult(settings=DetectSettings(), models=("m",), splits=(sp, by_exp), tests=(), decisions=(),
                          all_decisions=(), normality=(), design=())
    back = json.loads(dumps(detection_dict(det)))["splits"]
    assert back[0]["cal_sensors"] == [0, 1, 2, 3] and back[0]["val_sensors"] == [4, 5]
    assert back[1]["cal_sensors"] is None and back[1]["val_sensors"] is None
    # every field is written: the split rebuilt from results.json equals the original
    assert [Split(**d) for d in back] == [sp, by_exp]
    assert split_dict(sp)["description"] == sp.description


def test_a_time_window_split_writes_its_windows_and_a_split_without_window_does_not():
    from identification.studies.splits import time_window_splits
    sp, = time_window_splits([1.5])
    d = json.loads(dumps(split_dict(sp)))
    assert d["cal_window"] == ["-inf", 1.5] and d["val_window"] == [1.5, "inf"]
    assert Split(**d) == sp                       # rebuilt from results.json with its windows
    plain = split_dict(Split("exp", [0], [1, 2]))
    assert "cal_window" not in plain and "val_window" not in plain
