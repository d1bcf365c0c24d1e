"""What an evaluation game was played against, as its begin info says (docs/training.md, "What is logged"):
`tracelab eval --run` and a training's traced evaluations record the world's params (`"params": {...}`, as
its spec reads them); RuleSim's runs recorded their opponent's level alone (`"opponent_p": P`). Both viewers
(the TUI's evaluation games, the replay's note) read them through here, so they say it alike."""
from __future__ import annotations

import json
import math
from typing import Any

from tracelab.engine.terminal_text import printable

MAX_PARAMS_JSON = 1 << 16  # a run is anyone's: params longer than this read as none
MAX_PARAMS_TEXT = 200      # and they are shown cut to this many characters at most
# the begin info's params (JSON text, NULL where it has none) and an older run's level, as `params`, `level`
EVAL_PARAMS_COLUMNS = (f"(SELECT CASE WHEN length(p) <= {MAX_PARAMS_JSON} THEN p END "
                       "FROM (SELECT json_extract(begin_info, '$.params')::VARCHAR AS p)) AS params, "
                       "TRY_CAST(json_extract(begin_info, '$.opponent_p') AS DOUBLE) AS level")


def _value_text(value: Any) -> str:
    if isinstance(value, float) and math.isfinite(value):
        return f"{value:g}"
    return value if isinstance(value, str) else json.dumps(value, separators=(",", ":"))


def eval_params_text(params: str | None, level: float | None, max_chars: int = MAX_PARAMS_TEXT) -> str | None:
    """`k=v k=v` of the params' JSON text (a number as `%g`), `opponent p=P` of an older run's level, None
    when the begin info has neither (a params that is not a JSON object, or an empty one, reads as none);
    safe on a terminal (printable), cut to `max_chars` (at least 1) with an ellipsis."""
    try:
        parsed = json.loads(params) if params else None
        text = " ".join(f"{k}={_value_text(v)}" for k, v in parsed.items()) if isinstance(parsed, dict) else ""
    except (ValueError, RecursionError):  # not JSON, a number past int's digits, nested too deep
        text = ""
    if not text and level is not None:
        text = f"opponent p={level:g}"
    if not text:
        return None
    text = printable(text)
    return text if len(text) <= max_chars else text[:max(max_chars, 1) - 1] + "…"
