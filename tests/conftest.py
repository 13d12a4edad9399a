"""Set-up shared by the test files: the bench's folder on sys.path, and the slow tier.

``python -m pytest -n 2`` runs the fast tier (pyproject.toml's ``-m 'not slow'``);
``python -m pytest -n 2 -m slow`` the slow tier (.ci/slow: weekly and on demand). The slow tier
is listed here, in one place, so that the two tiers are read and changed together: whole files
(the plant zoo, the wild plants, the withheld catheters) and the tests that took about 5 s or
more on 2 busy cores (``pytest --durations=0``; several runs, load average 6-12). A name listed
here that its file no longer defines is an error, so the list cannot silently fall behind.
"""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

SLOW_FILES = frozenset({"test_withheld.py", "test_wild_plants.py", "test_zoo_bench.py", "test_zoo_catheters.py",
                        "test_zoo_plants.py"})
"""Files whose every test is in the slow tier."""

SLOW_TESTS = {
    "test_cli_demo.py": ("test_demo_json_and_files", "test_demo_markdown_shows_paper_beside_ours",
                         "test_demo_runs_from_a_folder_without_sample_data",
                         "test_demo_without_diagnosis_has_only_the_papers_tables"),
    "test_cli_device.py": ("test_ctrl_c_on_hyst_play_returns_the_knob", "test_home_fault_says_where_the_knobs_are",
                           "test_identify_on_a_sweep_played_on_the_robot",
                           "test_play_against_sim_robot_matches_the_offline_twin",
                           "test_play_faults_stop_return_and_write_nothing[fault2-no reply-False]",
                           "test_play_fault_from_sim_robot_subprocess_writes_nothing",
                           "test_play_speed_modes_on_jumps", "test_sim_robot_serves_the_catheter_hyst_simulate_runs",
                           "test_status_home_jog_on_sim_robot"),
    "test_cli_diagnose.py": ("test_diagnose_writes_report_model_and_plot",),
    "test_cli_model.py": ("test_compensate_warns_outside_the_identified_range",),
    "test_cli_startup.py": ("test_shell_completion_completes_commands_and_options",),
    "test_cli_track.py": ("test_ctrl_c_on_hyst_track_returns_the_knob",
                          "test_track_faults_stop_return_and_write_nothing[fault2-no reply-False]",
                          "test_track_on_sim_robot_logs_what_compensate_and_simulate_say",
                          "test_track_port_closed_mid_run"),
    "test_drive.py": ("test_an_input_lag_shows_in_the_current_as_in_the_tip",
                      "test_diagnose_names_the_input_lag_with_the_sweep", "test_the_cli_shows_where_the_delay_sits"),
    "test_emulator.py": ("test_a_served_twin_is_warm_before_its_first_move",),
    "test_experiment.py": ("test_full_demo_lands_within_30_percent_of_every_paper_cell",
                           "test_reduced_protocol_has_the_tables_structure",
                           "test_same_seed_same_bytes_other_seed_other_noise"),
    "test_identify.py": ("test_a_flat_no_longer_than_the_trackers_memory_does_not_place_its_edge",
                         "test_a_flat_of_the_records_last_few_samples_does_not_place_its_edge",
                         "test_a_loop_the_first_starts_miss_is_found_by_searching_further",
                         "test_a_parameter_the_record_cannot_fix_is_named",
                         "test_a_record_that_starts_at_a_wall_is_refused_not_returned_wrong",
                         "test_a_wall_that_holds_the_tip_is_censored_and_the_free_loop_recovered",
                         "test_an_edge_on_a_flat_a_few_hundredths_wide_is_not_claimed",
                         "test_an_edge_the_tip_and_the_current_place_apart_is_not_claimed_when_both_loops_fit",
                         "test_current_only_heights_follow_the_documented_assumption",
                         "test_current_only_recovers_edges_and_backlash",
                         "test_an_edge_the_record_cannot_place_within_half_a_degree_is_not_claimed",
                         "test_further_starts_never_trade_a_whole_loop_for_a_degenerate_one",
                         "test_identify_is_deterministic", "test_knob_columns_and_arguments",
                         "test_never_past_the_dead_zone",
                         "test_one_cycle_started_at_rest_is_enough", "test_past_the_dead_zone_but_not_the_backlash",
                         "test_stored_levels_for_detect_shift", "test_tip_fit_recovers_all_parameters",
                         "test_tip_fit_rmse_is_at_the_noise_level_and_uncertainties_are_sane",
                         "test_walls_that_hold_every_sample_are_no_wall_the_plain_fit_stands",
                         "test_y0_is_the_first_measured_tip_angle"),
    "test_live_detect.py": ("test_fault_mid_search_stops_safely[silent@5]", "test_timeout_is_the_reply_deadline"),
    "test_real.py": ("test_diagnose_names_the_stretch_across_real_loads_and_where_the_model_holds",
                     "test_real_excerpt_tip_fit_beats_a_linear_fit_in_sample_and_held_out",
                     "test_stretch_fitted_at_40_percent_predicts_the_real_30_percent_run"),
    "test_refit.py": ("test_a_two_knob_sweep_carries_a_bend_coupling_and_the_refit_takes_it_off",),
    "test_rotate_shift.py": ("test_rotate_shift_matches_detection_after_rotation",),
    "test_stream.py": ("test_step_gives_what_compensate_writes[nonperiodic-coupling-input]",),
}
"""Per file, the slow tests: a function's name (every case of it) or one case, ``name[id]``."""


@pytest.hookimpl(tryfirst=True)  # before -m deselects by the marker
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    modules = {}
    for item in items:
        file = item.path.name
        modules[file] = getattr(item, "module", None)
        listed = SLOW_TESTS.get(file, ())
        if file in SLOW_FILES or item.name in listed or getattr(item, "originalname", None) in listed:
            item.add_marker(pytest.mark.slow)
    gone = [f"{file}::{name}" for file, module in modules.items() if module is not None
            for name in SLOW_TESTS.get(file, ()) if not hasattr(module, name.split("[")[0])]
    if gone:
        raise pytest.UsageError(f"tests/conftest.py lists slow tests their files do not define: {', '.join(gone)}")
