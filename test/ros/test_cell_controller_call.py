"""The example cell controller's service calls: a request left unanswered is sent again only
where that is safe, and a call never waits past its timeout."""

from __future__ import annotations

import time

import pytest
from ros_test_tools import probe_node
from std_srvs.srv import Trigger

from feeder_ros.examples.cell_controller import CellController


def _late_server(node, delays_s: list[float]):  # type: ignore[no-untyped-def]
    """A Trigger server that answers request k after ``delays_s[k]`` (0 once the list ends)."""
    served: list[float] = []

    def on_request(request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        k = len(served)
        served.append(time.monotonic())
        time.sleep(delays_s[k] if k < len(delays_s) else 0.0)
        response.success = True
        response.message = f"answer {k + 1}"
        return response

    node.create_service(Trigger, "/call_test/slow", on_request)
    return served


def _controller(probe):  # type: ignore[no-untyped-def]
    """The controller on the probe's executor (its thread delivers the answers)."""
    controller = CellController("/call_test", context=probe.context)
    probe.executor.add_node(controller)
    return controller


def _drop(probe, controller: CellController) -> None:  # type: ignore[no-untyped-def]
    probe.executor.remove_node(controller)
    controller.destroy_node()


@pytest.mark.parametrize("ask_again_s", [2.0, None])
def test_an_unanswered_request_is_sent_again_only_when_repeatable(ask_again_s) -> None:  # type: ignore[no-untyped-def]
    with probe_node() as probe:
        served = _late_server(probe, [3.0])  # the first answer comes after the re-send
        controller = _controller(probe)
        try:
            answer = controller.call(
                Trigger, "slow", Trigger.Request(), timeout_s=20.0, ask_again_s=ask_again_s
            )
        finally:
            _drop(probe, controller)
    steps = [entry["step"] for entry in controller.timeline]
    if ask_again_s is None:
        assert (answer.message, len(served)) == ("answer 1", 1)
        assert "no answer, asking again" not in steps
    else:
        # the late first answer belongs to a request the controller gave up: the second counts
        assert (answer.message, len(served)) == ("answer 2", 2)
        assert steps.count("no answer, asking again") == 1


def test_a_call_gives_up_at_its_timeout_naming_the_service() -> None:
    with probe_node() as probe:
        served = _late_server(probe, [3.0, 3.0])
        controller = _controller(probe)
        try:
            start = time.monotonic()
            unanswered = r"service /call_test/slow did not answer in 1 s"
            with pytest.raises(RuntimeError, match=unanswered):
                controller.call(Trigger, "slow", Trigger.Request(), timeout_s=1.0)
            waited = time.monotonic() - start
        finally:
            _drop(probe, controller)
    assert 1.0 <= waited < 2.5, waited
    assert len(served) == 1
