"""The touch-cycle events of :mod:`tactile_common.cycle` <-> diagnostic_msgs/DiagnosticStatus."""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from .cycle import PlannerAnswer, PlanRequest, TouchOutcome, TouchReport


def values_of(msg: DiagnosticStatus) -> dict:
    return {kv.key: kv.value for kv in msg.values}


def _status(name: str, message: str, values: dict, level, hardware_id: str) -> DiagnosticStatus:
    return DiagnosticStatus(level=level, name=name, message=message, hardware_id=hardware_id,
                            values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])


def request_msg(request: PlanRequest) -> DiagnosticStatus:
    return _status("plan_request", "plan", request.values(), DiagnosticStatus.OK, "explorer")


def request_from_msg(msg: DiagnosticStatus) -> PlanRequest:
    return PlanRequest.from_values(values_of(msg))


def answer_msg(answer: PlannerAnswer) -> DiagnosticStatus:
    level = DiagnosticStatus.OK if answer.ok else DiagnosticStatus.WARN
    return _status("soc_planner", answer.status, answer.values(), level, "soc_planner")


def answer_from_msg(msg: DiagnosticStatus) -> PlannerAnswer:
    return PlannerAnswer.from_values(msg.message, values_of(msg))


_LEVEL = {TouchOutcome.UNREACHABLE: DiagnosticStatus.WARN, TouchOutcome.ABORTED: DiagnosticStatus.ERROR}


def report_msg(report: TouchReport) -> DiagnosticStatus:
    return _status("touch", report.outcome.value, report.values(), _LEVEL.get(report.outcome, DiagnosticStatus.OK),
                   "arm")


def report_from_msg(msg: DiagnosticStatus) -> TouchReport:
    return TouchReport.from_values(msg.message, values_of(msg))
