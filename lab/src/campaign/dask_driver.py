"""Runs the pending jobs of an excavator-ctl campaign plan on a Dask cluster (docs/campaigns.md).

Written beside the plan and started by `excavator-ctl ... --executor dask://HOST:PORT`; it needs
Python 3.9+ with the `distributed` package on this machine and on the workers. One task per job:
the worker runs the job's command line (the worker's excavator-ctl in place of the first word) as
a subprocess in the plan's work folder, which every worker sees at the same path. A job that exits
non-zero raises, and Dask retries it `--retries` times; a job on a worker that dies is rescheduled
by the scheduler. Every attempt is logged in campaign/attempts/ID.log; a finished job's done marker
(campaign/done/ID.json, the JobRecord of lab::campaign) is written here, as its task returns.
Exit status 0 when every job finished, 1 when some failed (listed), 2 on a bad argument.
"""

import argparse
import json
import os
import sys
import time


def run_job(job, binary, workdir, attempts_dir, threads):
    """The task: one attempt of `job` on this worker; its cost, or an exception on failure."""
    import os
    import socket
    import subprocess
    import time

    log = os.path.join(attempts_dir, job["id"] + ".log")
    start = time.time()
    with open(log, "a") as f:
        f.write(json.dumps({"event": "start", "host": socket.gethostname(), "pid": os.getpid(), "t": start}) + "\n")
    env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
    out_path = os.path.join(attempts_dir, "%s.%d.out" % (job["id"], os.getpid()))
    with open(out_path, "wb") as out:
        proc = subprocess.Popen([binary] + job["argv"][1:], cwd=workdir, env=env, stdout=out,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        _, status, usage = os.wait4(proc.pid, 0)
    code = os.waitstatus_to_exitcode(status)
    wall_s = time.time() - start
    with open(log, "a") as f:
        f.write(json.dumps({"event": "end", "pid": os.getpid(), "exit": code, "wall_s": wall_s}) + "\n")
    if code != 0:
        with open(out_path, "rb") as f:
            tail = f.read()[-2000:].decode("utf-8", "replace")
        raise RuntimeError("job %s exited with %d: %s" % (job["id"], code, tail))
    os.remove(out_path)
    return {
        "wall_s": wall_s,
        "cpu_s": usage.ru_utime + usage.ru_stime,
        "max_rss_kib": usage.ru_maxrss,
        "worker": socket.gethostname(),
    }


def attempts(attempts_dir, job_id):
    """Attempts of a job so far: the start lines of its log."""
    try:
        with open(os.path.join(attempts_dir, job_id + ".log")) as f:
            return sum(1 for line in f if '"event": "start"' in line)
    except OSError:
        return 1


def write_atomic(path, text):
    tmp = "%s.%d.tmp" % (path, os.getpid())
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scheduler", required=True, help="tcp://HOST:PORT")
    p.add_argument("--plan", required=True)
    p.add_argument("--pending", required=True, help="JSON list of the job ids to run")
    p.add_argument("--binary", required=True, help="the workers' excavator-ctl")
    p.add_argument("--retries", type=int, default=2)
    p.add_argument("--threads-per-job", type=int, default=1)
    a = p.parse_args()
    if not 0 <= a.retries <= 10 or not 1 <= a.threads_per_job <= 256:
        print("dask driver: --retries 0-10, --threads-per-job 1-256", file=sys.stderr)
        return 2
    try:
        from distributed import Client, as_completed
    except ImportError:
        print("dask driver: the Python package `distributed` is missing (pip install distributed)", file=sys.stderr)
        return 2
    plan_path = os.path.abspath(a.plan)
    with open(plan_path) as f:
        plan = json.load(f)
    with open(a.pending) as f:
        pending = json.load(f)
    jobs = {j["id"]: j for j in plan["jobs"]}
    unknown = [i for i in pending if i not in jobs]
    if unknown:
        print("dask driver: jobs %s are not in %s" % (unknown, plan_path), file=sys.stderr)
        return 2
    campaign = os.path.dirname(plan_path)
    attempts_dir = os.path.join(campaign, "attempts")
    done_dir = os.path.join(campaign, "done")
    os.makedirs(attempts_dir, exist_ok=True)
    os.makedirs(done_dir, exist_ok=True)
    for i in pending:
        # A log of an earlier run of the campaign: this run counts its own attempts.
        try:
            os.remove(os.path.join(attempts_dir, i + ".log"))
        except OSError:
            pass
    client = Client(a.scheduler, timeout="60s")
    workers = len(client.scheduler_info().get("workers", {}))
    print("dask driver: %d jobs on %s (%d workers)" % (len(pending), a.scheduler, workers), flush=True)
    run = "%x" % int(time.time() * 1e6)
    submitted = []
    for i in pending:
        fut = client.submit(run_job, jobs[i], a.binary, plan["workdir"], attempts_dir, a.threads_per_job,
                            key="excavator-%s-%s-%s" % (plan["kind"], run, i), retries=a.retries, pure=False)
        submitted.append((fut, i))
    job_of = {fut.key: i for fut, i in submitted}
    failed = []
    for fut in as_completed([fut for fut, _ in submitted]):
        i = job_of[fut.key]
        try:
            cost = fut.result()
        except Exception as e:  # noqa: BLE001 - every failure is reported
            failed.append((i, str(e)))
            print("dask driver: job %s failed after %d attempts: %s" % (i, attempts(attempts_dir, i), e),
                  file=sys.stderr, flush=True)
            continue
        record = {
            "id": i,
            "argv": jobs[i]["argv"],
            "worker": cost["worker"],
            "attempts": attempts(attempts_dir, i),
            "wall_s": cost["wall_s"],
            "cpu_s": cost["cpu_s"],
            "max_rss_kib": cost["max_rss_kib"],
        }
        write_atomic(os.path.join(done_dir, i + ".json"), json.dumps(record, indent=2))
    client.close()
    if failed:
        print("dask driver: %d of %d jobs failed: %s" % (len(failed), len(pending), ", ".join(i for i, _ in failed)),
              file=sys.stderr)
        return 1
    return 0

if __name__ == "__main__":
    sys.exit(main())
