"""The pilot table reads each report folder's predictors.csv and pairwise.csv."""

import pandas as pd

from analysis.pilot_table import means_table, pairs_table


def test_every_predictor_and_pair_of_every_pilot_is_a_row(tmp_path):
    folders = []
    for kind, err in (("coarse", 0.1), ("precise", 0.3)):
        folder = tmp_path / f"pilot_interaction_study_{kind}"
        folder.mkdir()
        pd.DataFrame({"participant_id": ["a", "b"], "world": ["ring", "ring"],
                      "err_ours": [err, err + 0.2], "err_vae": [0.5, 0.5],
                      "err_ctrv": [0.2, 0.4], "err_policy": [0.0, 0.0]}
                     ).to_csv(folder / "predictors.csv", index=False)
        pd.DataFrame([{"world": "ring", "a": "ours", "b": "vae", "mean_diff": -0.3,
                       "ci95_low": -0.4, "ci95_high": -0.2, "p_holm": 0.001,
                       "mixed_estimate": -0.3, "mixed_p_holm": 0.02, "mixed_status": "ok",
                       "verdict": "ours"}]).to_csv(folder / "pairwise.csv", index=False)
        folders.append(folder)
    means = means_table(folders)
    assert means[0] == "| pilot | world | ours | vae | ctrv | policy |"
    assert means[2:] == ["| coarse | ring | 0.200 | 0.500 | 0.300 | 0.000 |",
                         "| precise | ring | 0.400 | 0.500 | 0.300 | 0.000 |"]
    pairs = pairs_table(folders)
    assert pairs[2] == ("| coarse | ring | ours vs vae | -0.3000 [-0.4000, -0.2000] | 0.001 | "
                        "-0.3000, 0.02 (ok) | ours |")
    assert len(pairs) == 2 + 2
