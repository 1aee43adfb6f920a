"""A machine's calibrations over time: what the store holds, read as a trend, a step or a
drift, and a short check against the last accepted calibration.

Values compare across an edit: an edit written from a fit corrects that fit's location
errors, so after it the control should measure them less by as much. Each fit's *machine
value* is what it measured plus every correction written before it; a step or a drift is
judged on machine values, so an edit is never mistaken for a crash, and a crash after an
edit is still one.

The ledger (``ledger``), its reading as a trend (``drift``), the check against the last
calibration (``checks``), the words (``words``) and the move between stores (``exchange``);
what the commands use is named here."""

from __future__ import annotations

from .checks import (  # noqa: F401
    Change,
    CheckModel,
    CheckResult,
    calibration_accepted,
    check,
    fit_as_calibrated,
    record_check,
)
from .drift import (  # noqa: F401
    Entry,
    Flag,
    Trend,
    calibration_fit,
    drift_limits,
    flags,
    fleet,
    last_calibration,
    limit_of,
    machine_params,
    trend,
)
from .exchange import (  # noqa: F401
    EXPORT_FIELDS,
    EXPORT_FORMAT,
    check_export,
    export_all,
    export_rows,
    export_text,
    import_history,
)
from .ledger import (  # noqa: F401
    DATE,
    DAYS_PER_MONTH,
    DEVICES,
    EARLIEST,
    Recorded,
    content_key,
    days,
    edit_of,
    file_ref,
    lookup_machine,
    machine_id,
    machine_key,
    record_edit,
    record_fit,
    refuse_second_edit,
    session_and_fit,
    taken_at,
    utc,
)
from .words import (  # noqa: F401
    machines_text,
    trend_dict,
    trend_text,
)
