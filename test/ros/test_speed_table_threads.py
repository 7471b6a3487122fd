"""The drive interface computes a speed table that is not cached yet in its configure transition.
On a machine shared with the live cell it must leave a core to the other nodes: with every core
taken, a 2-core machine starved the simulator and the estimator raised a sensor timeout. Where
the table is cached is read at configure too."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numba
import pytest
import rclpy
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter

import feeder_ros.drive.speed_model_source as speed_model_source
import feeder_ros.nodes.drive_interface as drive_interface
from feeder_ros.drive.speed_model import cached_speed_table


def test_speed_table_is_computed_with_a_core_left_free(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[int] = []

    def recording(*args: Any, **kwargs: Any) -> Any:
        seen.append(numba.get_num_threads())
        return cached_speed_table(*args, **kwargs)

    monkeypatch.setattr(speed_model_source, "cached_speed_table", recording)
    threads_before = numba.get_num_threads()
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = drive_interface.DriveInterface(
            context=context,
            parameter_overrides=[
                Parameter("speed_model_cache_dir", value=str(tmp_path)),
                Parameter("speed_model_frequency_steps", value=5),
                Parameter("speed_model_amplitude_steps", value=3),
                Parameter("speed_model_duration_s", value=0.5),
            ],
        )
        try:
            assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
            # the cache directory is read at configure: a change now would act only at the next
            # configure, so it is refused like the table's other inputs
            [moved] = node.set_parameters(
                [Parameter("speed_model_cache_dir", value=str(tmp_path / "elsewhere"))]
            )
            assert not moved.successful
            assert moved.reason.startswith("speed_model_cache_dir is read at configure")
            assert node.get_parameter("speed_model_cache_dir").value == str(tmp_path)
        finally:
            node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert seen == [min(threads_before, max(1, (os.cpu_count() or 1) - 1))]
    assert len(list(tmp_path.glob("speed_table_*.npz"))) == 1  # the table was computed and cached
    assert numba.get_num_threads() == threads_before  # restored after the configure
