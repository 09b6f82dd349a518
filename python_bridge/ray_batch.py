"""Runs a garmentbake batch plan on a Ray cluster: one Ray task per job.

Embedded in the garmentbake binary (src/batch/ray.rs) and run by `garmentbake batch run --ray
ADDRESS` with the project venv's Python; usable on its own too:

    python ray_batch.py --address HOST:PORT --plan OUT/plan.json --exe /shared/garmentbake [--retries N]

Each task asks for the job's `resources` (CPUs, GPUs) and receives the outcomes of the jobs it
depends on as task references, so Ray orders the graph; a task whose upstream did not succeed
returns `skipped` without running. The task itself runs `garmentbake batch job --plan P --id ID`,
the same code the local runner uses (skip when the outputs carry the key, logs, retries, keys
written last). Paths in the plan are absolute: the binary, the inputs and the output folder must
be on a path every node sees. Prints the outcomes as one JSON list on stdout.
"""
import argparse
import json
import subprocess
import sys

import ray


def run_job(exe, plan, job, retries, *upstream):
    """One job; `upstream` are the outcomes of its dependencies (resolved by Ray)."""
    for dep in upstream:
        if dep["status"] not in ("ran", "up-to-date"):
            return {
                "id": job["id"], "status": "skipped", "seconds": 0.0, "attempts": 0,
                "outputs": job["outputs"], "metrics": {}, "log": job["log"],
                "error": "not run: %s did not succeed" % dep["id"],
            }
    done = subprocess.run(
        [exe, "batch", "job", "--plan", plan, "--id", job["id"], "--retries", str(retries)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        return json.loads(done.stdout)
    except ValueError:
        return {
            "id": job["id"], "status": "failed", "seconds": 0.0, "attempts": 1,
            "outputs": job["outputs"], "metrics": {}, "log": job["log"],
            "error": "batch job exited %s: %s" % (done.returncode, done.stderr.strip()[-500:]),
        }


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--address", required=True)
    p.add_argument("--plan", required=True)
    p.add_argument("--exe", required=True)
    p.add_argument("--retries", type=int, default=0)
    a = p.parse_args()
    with open(a.plan) as f:
        plan = json.load(f)
    ray.init(address=a.address, logging_level="ERROR", log_to_driver=False)
    gpus = ray.cluster_resources().get("GPU", 0)
    task = ray.remote(run_job)
    refs = {}
    for job in plan["jobs"]:  # dependency order: every dependency already has its reference
        res = job["resources"]
        if res["gpus"] and not gpus:
            sys.exit("error: job %s asks for a GPU and the cluster at %s has none" % (job["id"], a.address))
        refs[job["id"]] = task.options(
            num_cpus=res["cpus"], num_gpus=res["gpus"], max_retries=a.retries, name=job["id"]
        ).remote(a.exe, a.plan, job, a.retries, *[refs[d] for d in job["deps"]])
    outcomes = ray.get([refs[j["id"]] for j in plan["jobs"]])
    json.dump(outcomes, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
