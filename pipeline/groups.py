"""How the workflow cuts a run into jobs (pipeline/Snakefile; also
scripts/bench-ingest-jobs, which runs the same jobs by hand): stores into
groups by their names under a size, and ingest's input parts into read
groups the same way."""
import os


def split_groups(stores, limit):
    """A level's stores [(name, bytes)] in groups of at most `limit` bytes
    where it can: the level is one group if it fits; one that does not is
    split by the next character of the names (a state's counties, then a
    county's tracts: GEOID prefixes), and its parts that fit are joined
    again, in name order, into groups up to `limit`. Only the group that
    grew is split, so the groups of one state do not change when another
    does. {group name: (store names, selection)}: `g51` (the stores whose
    names begin with 51), `g510-514` (those of 510 to 514), or `s51` (the
    store named 51 where it is also a prefix of others); the selection is
    the group's --partitions items without the level."""
    groups = {}

    def place(prefix, members):
        size = sum(b for _, b in members)
        if size <= limit or max(len(n) for n, _ in members) == len(prefix):
            groups["g" + prefix] = ([n for n, _ in members], [prefix + "*"])
            return
        children = {}
        for n, b in members:
            if len(n) == len(prefix):
                groups["s" + n] = ([n], [n])
            else:
                children.setdefault(n[: len(prefix) + 1], []).append((n, b))
        run, run_bytes = [], 0

        def close():
            if run:
                name = run[0] if len(run) == 1 else f"{run[0]}-{run[-1]}"
                groups["g" + name] = ([n for c in run for n, _ in children[c]], [c + "*" for c in run])
            run.clear()

        for child in sorted(children):
            child_bytes = sum(b for _, b in children[child])
            if child_bytes > limit:
                close()
                run_bytes = 0
                place(child, children[child])
                continue
            if run and run_bytes + child_bytes > limit:
                close()
                run_bytes = 0
            run.append(child)
            run_bytes += child_bytes
        close()

    if stores:
        place("", stores)
    return groups


def part_ranges(numbers):
    """Sorted part numbers as --select ranges: [0, 1, 2, 4] -> "0-2,4"."""
    out, start = [], None
    for k, n in enumerate(numbers):
        if start is None:
            start = n
        if k + 1 == len(numbers) or numbers[k + 1] != n + 1:
            out.append(str(start) if start == n else f"{start}-{n}")
            start = None
    return ",".join(out)


# A read job's input bytes against a group's store bytes (workflow.job_mb):
# reading is about 20x faster a byte than colouring and simplifying (the 100
# M nation: 2.8 GB of zips read in 57 job-seconds), so its groups are 8x
# larger. At 32 MB groups a read job took 0.6 s at most, under the 5 s a
# Slurm submission costs: 147 read jobs at 100 M, whose submissions made
# the run on 8 workers slower than one plan reading everything (the
# estimate: 28.5 min against 27.0). At 256 MB, 16 jobs of about 4 s.
READ_FACTOR = 8


def read_groups_of(listing, job_bytes):
    """Ingest's read jobs from its listing (tigerlod-ingest --list's
    reads.json): the parts in groups of at most READ_FACTOR x `job_bytes`
    input bytes where it can, by split_groups on the parts' names (a TIGER
    state's counties together; a group changes only when its own parts do).
    {group: {"select": "0-4,7", "files": [...]}}; empty where the dataset
    is read by one job."""
    limit = READ_FACTOR * job_bytes
    # Names without the prefix every part has, cut back to a word's end
    # (tl_2020_51063_faces -> 51063_faces): the groups' names are short.
    names = [p["name"] for p in listing["parts"]]
    common = os.path.commonprefix(names) if len(names) > 1 else ""
    while common and common[-1].isalnum():
        common = common[:-1]
    named = {}
    for p in listing["parts"]:
        name = p["name"][len(common):]
        named[name if name not in named else f"{name}-{p['part']}"] = p
    groups = {}
    for group, (names, _) in split_groups(sorted((n, p["bytes"]) for n, p in named.items()), limit).items():
        parts = sorted((named[n] for n in names), key=lambda p: p["part"])
        groups[group] = {
            "select": part_ranges([p["part"] for p in parts]),
            "files": [f for p in parts for f in p["files"]],
        }
    return groups
