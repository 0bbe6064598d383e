"""pipeline/regions.py CONFIG CODES | --out CONFIG: for scripts/workflow.

CONFIG CODES: first the config is checked as the stages read it (a key
given twice, a document that is not a mapping: one line and exit 2); then
the outputs of the jobs a region rebuild forces, one a line:
the color job (the simplify job where simplify.shortcut_test is or takes
exact: pipeline/shortcut_test.py) of
every group of stores holding a store whose partition
begins with one of the codes (its own stores and those below) or is part of
one (the stores of its county and state, which hold its boundaries), and
every level held in a single store (the nation's map), and the ingest job
of every region whose codes begin with one of the codes or are part of one
(its stores rebuilt from the inputs: a store damaged by hand is written
again); simplify, pack, verify and render follow by dependency. CODES
is a comma-separated list; empty, the config's `regions` key. The groups
are the last run's (out/<name>/jobs/groups.json); without one nothing is
forced (every job runs anyway). A code that matches no store: a message
and exit 2.

--out CONFIG: out/<name>, the run's folder (empty if the config has no
usable name; the Snakefile says why)."""
import glob
import json
import os
import re
import sys

import yaml

from shortcut_test import resolve as resolve_shortcut_test


class ConfigError(Exception):
    pass


class UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing a key given twice in one mapping: the
    stages (yaml-cpp) read the first, PyYAML the last, so a duplicate would
    give the workflow and the stages two values."""

    def construct_mapping(self, node, deep=False):
        first = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            try:
                line = first.setdefault(key, key_node.start_mark.line + 1)
            except TypeError:  # an unhashable key: the stages refuse it
                continue
            if line != key_node.start_mark.line + 1:
                raise ConfigError(f"{key_node.start_mark.line + 1}: duplicate key '{key}' "
                                  f"(first at line {line}): give each key once")
        return super().construct_mapping(node, deep)


def die(message):
    print(message, file=sys.stderr)
    sys.exit(2)


def check_config(path):
    """The config as a dict, or a one-line message and exit 2 (the README's
    promise for a bad config): not YAML, a key given twice, not a mapping."""
    try:
        with open(path) as f:
            cfg = yaml.load(f, Loader=UniqueKeyLoader)
    except OSError as e:
        die(f"workflow: {path}: cannot read: {e.strerror}")
    except ConfigError as e:
        die(f"workflow: {path}:{e}")
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f":{mark.line + 1}" if mark is not None else ""
        die(f"workflow: {path}{where}: not valid YAML: {getattr(e, 'problem', None) or e}")
    if not isinstance(cfg, dict):
        kind = "empty" if cfg is None else f"a {type(cfg).__name__}"
        die(f"workflow: {path}: the config must be a mapping of keys (name, dataset, levels, ...), not {kind}")
    return cfg


def config_of(path):
    try:
        with open(path) as f:
            cfg = yaml.safe_load(f)
        return cfg if isinstance(cfg, dict) else {}
    except (OSError, yaml.YAMLError):
        return {}


def main():
    if sys.argv[1] == "--out":
        name = config_of(sys.argv[2]).get("name")
        print(f"out/{name}" if isinstance(name, str) and re.fullmatch(r"[a-z0-9_-]+", name) else "")
        return 0
    cfg = check_config(sys.argv[1])
    codes = sys.argv[2] if len(sys.argv) > 2 else ""
    if codes:
        regions = [c.strip() for c in codes.split(",") if c.strip()]
    else:
        given = cfg.get("regions") or []
        regions = [str(c) for c in (given if isinstance(given, list) else [given])]
    if not regions:
        return 0
    name = cfg.get("name")
    groups_file = f"out/{name}/jobs/groups.json"
    if not os.path.exists(groups_file):
        print(f"workflow: regions {','.join(regions)}: no earlier run in out/{name}; every job runs",
              file=sys.stderr)
        return 0
    with open(groups_file) as f:
        groups = json.load(f)
    # A level in one store (the nation's map, a state level named after the
    # nation's code) holds every region's boundaries at that level.
    stores_of_level = {}
    for g in groups:
        stores_of_level[g["level"]] = stores_of_level.get(g["level"], 0) + len(g["partitions"])
    # The first job of a group: its colouring, or its simplify where
    # simplify.shortcut_test is exact (no colouring).
    simplify = cfg.get("simplify") if isinstance(cfg.get("simplify"), dict) else {}
    first = "simplify" if resolve_shortcut_test(simplify)[0] == "exact" else "color"
    forced = []
    for region in regions:
        own = [g for g in groups if any(p.startswith(region) or region.startswith(p) for p in g["partitions"])]
        hits = [g for g in groups if g in own or stores_of_level[g["level"]] == 1]
        if not own:
            print(f"workflow: region {region} matches no store of out/{name} (stores are named by the codes of "
                  f"their units' parents, e.g. a county's tracts by its 5-digit code)", file=sys.stderr)
            return 2
        for g in hits:
            target = f"out/{name}/jobs/{first}/{g['level']}/{g['group']}.json"
            if target not in forced:
                forced.append(target)
    # The ingest jobs of the regions (their specs name their own codes).
    ingest = []
    for spec_path in sorted(glob.glob(f"out/{name}/ingest-jobs/jobs/*.json")):
        try:
            with open(spec_path) as f:
                spec = json.load(f)
        except (OSError, ValueError):
            continue
        own = (spec.get("region") or {}).get("own") or []
        if any(c.startswith(r) or r.startswith(c) for c in own for r in regions):
            ingest.append(f"out/{name}/ingest-jobs/shares/{spec['job']}.share")
    forced = ingest + forced
    print(f"workflow: regions {','.join(regions)}: forcing {len(ingest)} ingest and {len(forced) - len(ingest)} group "
          f"jobs and what depends on them", file=sys.stderr)
    print("\n".join(forced))
    return 0


if __name__ == "__main__":
    sys.exit(main())
