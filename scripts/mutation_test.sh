#!/usr/bin/env bash
# Mutation testing (mutmut 3) of modules that carry contracts: small bugs put into the code one at a time,
# each run against the tests that cover the mutated function. By hand or on a schedule, not in CI (tens of
# minutes a module on 2 cores). Where each module stands: docs/testing.md; each run and its survivors: docs/notes/test-runs.md.
#
#   pip install mutmut
#   bash scripts/mutation_test.sh WORKDIR MODULE.py [MODULE.py ...] -- TEST_PATH [TEST_PATH ...]
#   e.g. bash scripts/mutation_test.sh /tmp/mut geodata/stages/normalize.py -- tests/geodata/test_stages.py
#   SAMPLE=60 bash scripts/mutation_test.sh ...   # a random sample of 60 mutants (seed 0) where each takes minutes
#
# WORKDIR gets a copy of the committed tree (git archive HEAD), the installed compiled modules beside their
# packages, and a virtual environment that sees this one's packages but not its editable install (whose
# import hook would load the original sources instead of mutmut's copies). Prints the kill rate per module.
set -euo pipefail
work=${1:?usage: mutation_test.sh WORKDIR MODULE.py... -- TEST_PATH...}
shift
modules=()
while (( $# )) && [[ $1 != -- ]]; do modules+=("$1"); shift; done
(( $# )) && shift
tests=("$@")
(( ${#modules[@]} && ${#tests[@]} )) || { echo "usage: mutation_test.sh WORKDIR MODULE.py... -- TEST_PATH..." >&2; exit 2; }

repo=$(git rev-parse --show-toplevel)
python=$(command -v python)
site=$("$python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
"$python" -c 'import mutmut' 2> /dev/null || { echo "mutation_test.sh: pip install mutmut first" >&2; exit 2; }

rm -rf "$work"
mkdir -p "$work"
git -C "$repo" archive HEAD | tar -x -C "$work"
ln -s "$(realpath "$repo/../shared")" "$work/shared"  # the tests look for ../shared from mutants/tests/...
for package in geodata gegnn; do
    cp "$site/$package/"_*.so "$work/$package/"
done
"$python" -m venv "$work/.venv"
echo "$site" > "$("$work/.venv/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')/installed.pth"

quote() { printf '"%s", ' "$@"; }
cat >> "$work/pyproject.toml" <<EOF

[tool.mutmut]
source_paths = ["geodata", "gegnn"]
only_mutate = [$(quote "${modules[@]}")]
pytest_add_cli_args_test_selection = [$(quote "${tests[@]}")]
pytest_add_cli_args = ["-p", "no:cacheprovider"]
EOF

cd "$work"
# joblib sequential: mutmut 3.8 reaps its children with os.wait and stops with a KeyError when the pid is a
# loky worker that the tests left in its process (tests of parallel preparation).
# One OpenMP thread: mutmut forks its workers from a process whose tests started torch's thread pool, and
# a forked child waits forever on that pool (each such mutant then ends as a timeout).
export JOBLIB_MULTIPROCESSING=0 OMP_NUM_THREADS=1
if [[ -n ${SAMPLE:-} ]]; then
    # generate the mutants (then mutmut stops: the pattern names none of them), and run a sample of them
    .venv/bin/python -m mutmut run 'none-of-them' > mutmut-run.log 2>&1 ||
        grep -q "nothing matches" mutmut-run.log || { tail -30 mutmut-run.log; exit 1; }
    mapfile -t names < <(.venv/bin/python -m mutmut results --all true |
        sed -n 's/^ *\([^ :]*__mutmut_[0-9]*\):.*/\1/p' | shuf -n "$SAMPLE" --random-source=<(yes))
    .venv/bin/python -m mutmut run "${names[@]}" >> mutmut-run.log 2>&1 || { tail -30 mutmut-run.log; exit 1; }
    .venv/bin/python -m mutmut results --all true | grep -F -f <(printf '%s:\n' "${names[@]}") > mutmut-results.txt
else
    .venv/bin/python -m mutmut run > mutmut-run.log 2>&1 || { tail -30 mutmut-run.log; exit 1; }
    .venv/bin/python -m mutmut results --all true > mutmut-results.txt
fi
.venv/bin/python - "${modules[@]}" <<'EOF'
import re, sys
from collections import Counter

rows = Counter()
for line in open("mutmut-results.txt"):
    m = re.match(r"\s*([\w.]+)__mutmut_\d+: (.+)", line)
    if m:
        rows[(m.group(1), m.group(2).strip())] += 1
modules = {name.removesuffix(".py").replace("/", ".") for name in sys.argv[1:]}
print("| module | mutants | killed | survived | other | kill rate |\n|---|---:|---:|---:|---:|---:|")
for module in sorted(modules):
    got = Counter()
    for (name, status), n in rows.items():
        if name.startswith(module + "."):
            got[status] += n
    total = sum(got.values())
    killed, survived = got["killed"], got["survived"]
    rate = f"{100 * killed / (killed + survived):.0f}%" if killed + survived else "-"
    print(f"| {module} | {total} | {killed} | {survived} | {total - killed - survived} | {rate} |")
EOF
echo "surviving mutants: cd $work && .venv/bin/python -m mutmut show NAME   (names in $work/mutmut-results.txt)"
