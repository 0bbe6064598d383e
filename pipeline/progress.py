"""Snakemake log handler (--log-handler-script) for scripts/workflow: one
line per finished or failed job, `[done/total] stage level/group seconds`,
and on a terminal a progress bar for the run (percent, jobs a minute, ETA)
rewritten in place below them. TIGERLOD_PROGRESS=bar draws the bar on a
pipe too; TIGERLOD_PROGRESS=json prints each event as one JSON object a
line instead (for an engine above this one).

The bar never goes back. Snakemake's total grows at each checkpoint (the
plan and ingest's finish decide the jobs after them), so done / total can
fall (75 % to 48 % when the stages' group jobs appear); the bar shows the
largest fraction it has shown until done / total passes it again, and says
`+` after the total while a checkpoint may still add jobs (until a job of
the stages after ingest has been seen)."""
import json
import os
import sys
import time

_mode = os.environ.get("TIGERLOD_PROGRESS", "")
_bar = _mode == "bar" or (_mode == "" and sys.stderr.isatty())
_jobs = {}
_state = {"done": 0, "total": 0, "t0": time.time(), "bar": False, "text": None, "shown": 0.0, "final": False}
# Jobs of the stages after ingest's last checkpoint: once one is seen, the total is final.
_AFTER_CHECKPOINTS = ("color", "simplify", "pack", "verify", "render", "frame")
# Snakemake's own lines that this handler replaces or that say nothing to
# an operator; everything else it says (errors above all) is passed on.
_NOISE = ("Building DAG of jobs", "Using shell:", "Provided cores:", "Rules claiming more threads",
          "Select jobs to execute", "Job stats:", "Complete log:", "Updating job", "Finished job",
          "steps (", "unable to collect", "Conda environments:", "Singularity containers:", "Assuming unrestricted shared filesystem")
_PASSED = ("error", "warning", "job_error", "group_error", "info")


def _name(info):
    rule = info.get("name", "?")
    wc = info.get("wildcards") or {}
    stage = rule.split("_")[0]
    where = "/".join(str(wc[k]) for k in ("level", "group") if k in wc)
    if "job" in wc:  # an ingest region's job: `ingest r-44`
        return f"{stage} {wc['job']}"
    if "read" in wc:  # an ingest read job: `ingest read g0`
        return f"{stage} read {wc['read']}"
    return f"{stage} {where}".strip() if rule.endswith("_group") else rule.replace("_", " ")


def _clear_bar():
    if _state["bar"]:
        sys.stderr.write("\r\033[K")
        _state["bar"] = False


def bar_fraction(done, total):
    """The fraction the bar shows: done / total, never below what it showed before."""
    if total > 0:
        _state["shown"] = max(_state["shown"], min(1.0, done / total))
    return _state["shown"]


def _draw_bar():
    done, total = _state["done"], _state["total"]
    if not _bar or total == 0:
        return
    fraction = bar_fraction(done, total)
    elapsed = time.time() - _state["t0"]
    rate = done / elapsed if elapsed > 0 else 0.0
    eta = (total - done) / rate if rate > 0 else 0.0
    width = 30
    filled = int(width * fraction)
    more = "" if _state["final"] else "+"
    sys.stderr.write(
        f"\r[{'#' * filled}{'.' * (width - filled)}] {100.0 * fraction:5.1f}% {done}/{total}{more} jobs, "
        f"{60 * rate:.1f} jobs/min, ETA {int(eta) // 60}:{int(eta) % 60:02d}{more} "
    )
    sys.stderr.flush()
    _state["bar"] = True


def _take_over_text():
    """Snakemake's text handler prints every job's rule block; this handler
    takes its place and passes on what is not noise."""
    if _state["text"] is None:
        from snakemake.logging import logger

        _state["text"] = logger.text_handler
        if logger.text_handler in logger.log_handler:
            logger.log_handler.remove(logger.text_handler)
    return _state["text"]


def log_handler(msg):
    text = _take_over_text()
    level = msg.get("level")
    if level in _PASSED or (level == "shellcmd" and os.environ.get("TIGERLOD_SHELLCMDS")):
        said = str(msg.get("msg", ""))
        if level != "info" or not any(n in said for n in _NOISE):
            _clear_bar()
            text(msg)
    now = msg.get("timestamp", time.time())
    if _mode == "json":
        if level in ("job_info", "job_finished", "job_error", "progress"):
            out = {k: v for k, v in msg.items() if k in ("level", "jobid", "name", "wildcards", "done", "total")}
            out["time"] = now
            print(json.dumps(out, default=str), file=sys.stderr, flush=True)
        return
    if level == "job_info":
        _jobs[msg.get("jobid")] = (_name(msg), now)
        if str(msg.get("name", "")).split("_")[0] in _AFTER_CHECKPOINTS:
            _state["final"] = True
    elif level == "progress":
        _state["done"], _state["total"] = msg.get("done", 0), msg.get("total", 0)
        _draw_bar()
    elif level == "job_finished":
        name, start = _jobs.pop(msg.get("jobid"), ("job", now))
        _clear_bar()
        print(f"[{_state['done'] + 1}/{_state['total'] or '?'}] {name}: {now - start:.1f} s", file=sys.stderr,
              flush=True)
    elif level == "job_error":
        name, _ = _jobs.pop(msg.get("jobid"), (_name(msg), now))
        _clear_bar()
        print(f"FAILED {name}", file=sys.stderr, flush=True)
