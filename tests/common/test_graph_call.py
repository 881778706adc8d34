"""The test graph's service call resends an idempotent request whose answer was lost."""

import pytest
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.task import Future
from std_srvs.srv import Trigger

from tactile_common.testing import GraphTestError


def test_call_resends_when_the_first_answer_never_comes(ros_graph):
    seen = []
    never = Future()

    async def drop_first(request, response):
        seen.append(request)
        if len(seen) == 1:
            await never  # never answered, like a response lost before matching
        response.success = True
        response.message = f"request {len(seen)}"
        return response

    # A reentrant group lets the second request in while the first one waits.
    server = ros_graph.node.create_service(Trigger, "/drop_first", drop_first,
                                             callback_group=ReentrantCallbackGroup())
    reply = ros_graph.call(Trigger, "/drop_first", Trigger.Request(), timeout_s=20,
                           what="the answer", answer_within_s=0.5)
    assert reply.success and reply.message == "request 2" and len(seen) == 2
    ros_graph.node.destroy_service(server)


def test_call_gives_up_at_its_timeout(ros_graph):
    never = Future()

    async def silent(request, response):
        await never
        return response

    ros_graph.node.create_service(Trigger, "/silent", silent)
    with pytest.raises(GraphTestError, match="the silent answer"):
        ros_graph.call(Trigger, "/silent", Trigger.Request(), timeout_s=1.5, what="the silent answer",
                       answer_within_s=0.5)
