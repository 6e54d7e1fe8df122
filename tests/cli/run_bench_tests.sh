#!/usr/bin/env bash
# The evaluation benchmarks run end to end and write what they promise. Two parts, run
# as two tests:
#   fit        two cases of the quick grid with every setting: results.csv with its
#              columns, curves, RESULTS.md, the work-precision settings, ours ahead of
#              the baselines on each case; --defaults-only, --sample, --methods and
#              --cases give the same rows. (The whole grid's medians are the benchmark's
#              own to report: `organfit bench fit --quick`.)
#   stability  the stability matrix with every row passing, a twist seen from one side,
#              and bench scale on the prostate.
# Prints "N passed, N failed".
set -u
bin="${ORGANFIT:?set ORGANFIT to the organfit binary}"
part="${1:?usage: run_bench_tests.sh fit|stability}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
passed=0
failed=0
check() {  # check NAME CONDITION...
  local name="$1"
  shift
  if "$@"; then echo "ok   $name"; passed=$((passed + 1)); else echo "FAIL $name"; failed=$((failed + 1)); fi
}

if [[ $part == fit ]]; then
# Two cases of the quick grid (the prostate bent 10 mm, the cube indented 5 mm), every
# method at every setting of its effort.
"$bin" --quiet bench fit --quick --cases 4,17 --out "$tmp/fit" > "$tmp/fit.json" 2> "$tmp/fit.err"
check bench.fit_runs test $? -eq 0
check bench.fit_results_csv_columns /usr/bin/python3 -c "
import csv
rows = list(csv.DictReader(open('$tmp/fit/results.csv')))
need = 'method,shape,family,magnitude_mm,points,noise_mm,outliers,wall_s,msd_mm,hd95_mm,dice,volume_change_pct,volume_change_lattice_pct'.split(',')
assert all(k in rows[0] for k in need), rows[0].keys()
# The volume change by the Jacobian and by the lattice's count agree on the prostate (no
# flat face for the lattice to quantise) within a few tenths of a percent.
assert all(abs(float(r['volume_change_pct']) - float(r['volume_change_lattice_pct'])) < 0.5 for r in rows if r['case'] == '4'), [(r['volume_change_pct'], r['volume_change_lattice_pct']) for r in rows]
assert [(r['method'], r['case']) for r in rows] == [(m, c) for c in ('4', '17') for m in ('spread', 'paper', 'tps', 'cpd', 'icp')], rows
assert [(r['shape'], r['family'], r['magnitude_mm']) for r in rows[::5]] == [('phantom_prostate', 'bend', '10'), ('cube', 'indent', '5')]
assert all(0 <= float(r['dice']) <= 1 and float(r['msd_mm']) >= 0 for r in rows)
assert all((r['msd_global_mm'] == 'nan') == (r['method'] != 'spread') for r in rows)"
check bench.fit_curves_and_plot /usr/bin/python3 -c "
import xml.dom.minidom
lines = open('$tmp/fit/curves.csv').read().splitlines()
assert lines[0] == 'case,method,step,wall_s,residual_mean_mm,volume_change_pct' and len(lines) > 20
xml.dom.minidom.parse('$tmp/fit/work_precision.svg')"
check bench.fit_results_md grep -q "MSD <= 1.0 mm:" "$tmp/fit/RESULTS.md"
# Work precision: every case has each method at each setting of its effort, the default
# setting's row is the one in results.csv, and the plot has one curve per method.
check bench.fit_work_precision_settings /usr/bin/python3 -c "
import csv, xml.dom.minidom
rows = list(csv.DictReader(open('$tmp/fit/work_precision.csv')))
settings = {(r['method'], r['effort']) for r in rows}
assert settings == {('spread', 'global stage'), ('spread', 'global and local stages'),
                    ('paper', 'default'), ('tps', '1 round'), ('tps', '2 rounds'),
                    ('tps', '5 rounds'), ('tps', '10 rounds'), ('cpd', '15 iterations'),
                    ('cpd', '50 iterations'), ('cpd', '150 iterations'), ('icp', '3 iterations'),
                    ('icp', '10 iterations'), ('icp', '30 iterations')}, settings
assert len(rows) == 2 * len(settings), len(rows)
default = {'spread': 'global and local stages', 'paper': 'default', 'tps': '5 rounds',
           'cpd': '150 iterations', 'icp': '30 iterations'}
main = {(r['method'], r['case']): r for r in csv.DictReader(open('$tmp/fit/results.csv'))}
for r in rows:
  if r['effort'] == default[r['method']]:
    m = main[(r['method'], r['case'])]
    assert abs(float(m['msd_mm']) - float(r['msd_mm'])) < 1e-3 and abs(float(m['wall_s']) - float(r['wall_s'])) < 1e-3, (r, m)
  # less effort takes less time (TPS's rounds are one run stopped there)
  if r['method'] == 'tps' and r['effort'] == '1 round':
    assert float(r['wall_s']) <= float(main[('tps', r['case'])]['wall_s']), r
svg = xml.dom.minidom.parse('$tmp/fit/work_precision.svg')
assert len(svg.getElementsByTagName('polyline')) == 5"
# Ours against the baselines, case by case (the quick grid's medians are bench fit
# --quick's to report): closer than TPS and CPD, the volume kept within 1% where TPS's
# changes more.
check bench.fit_ours_ahead_on_each_case /usr/bin/python3 -c "
import csv
rows = {(r['method'], r['case']): r for r in csv.DictReader(open('$tmp/fit/results.csv'))}
for c in ('4', '17'):
  ours = rows[('spread', c)]
  assert float(ours['msd_mm']) < 0.8 and float(ours['hd95_mm']) < 2.0, ours
  assert abs(float(ours['volume_change_pct'])) < 1.0, ours
  for b in ('tps', 'cpd'):
    assert float(ours['msd_mm']) < float(rows[(b, c)]['msd_mm']), (c, b)
    assert abs(float(ours['volume_change_pct'])) < abs(float(rows[(b, c)]['volume_change_pct'])), (c, b)"
# --defaults-only: the same rows, one setting per method, no equal-time comparison.
"$bin" --quiet bench fit --quick --defaults-only --cases 4,17 --out "$tmp/defaults" > "$tmp/defaults.json" 2> /dev/null
check bench.fit_defaults_only_same_rows /usr/bin/python3 -c "
import csv, json
key = lambda r: (r['method'], r['case'])
whole = {key(r): r for r in csv.DictReader(open('$tmp/fit/results.csv'))}
part = list(csv.DictReader(open('$tmp/defaults/results.csv')))
assert [key(r) for r in part] == list(whole), part
for r in part:
  assert r['msd_mm'] == whole[key(r)]['msd_mm'] and r['volume_change_pct'] == whole[key(r)]['volume_change_pct'], key(r)
wp = list(csv.DictReader(open('$tmp/defaults/work_precision.csv')))
assert len({(r['method'], r['effort']) for r in wp}) == 6 and len(wp) == 12, wp
j = json.load(open('$tmp/defaults.json'))
assert j['defaults_only'] and 'at_equal_wall_time' not in j['versus_tps'], j
assert '--defaults-only' in open('$tmp/defaults/RESULTS.md').readline()"
# --sample and --methods: a seeded subset of the grid, only those methods, and the same
# rows as when those cases are run by number.
"$bin" --quiet bench fit --quick --defaults-only --sample 2 --methods icp,spread --out "$tmp/sample" > "$tmp/sample.json" 2> /dev/null
sampled="$(/usr/bin/python3 -c "
import csv
print(','.join(sorted({r['case'] for r in csv.DictReader(open('$tmp/sample/results.csv'))}, key=int)))")"
"$bin" --quiet bench fit --quick --defaults-only --cases "$sampled" --methods spread,icp --out "$tmp/again" > /dev/null 2>&1
check bench.fit_sample_and_methods_run_the_same_cases /usr/bin/python3 -c "
import csv, json
key = lambda r: (r['method'], r['shape'], r['family'], r['magnitude_mm'], r['points'], r['noise_mm'], r['outliers'], r['case'])
part = list(csv.DictReader(open('$tmp/sample/results.csv')))
again = {key(r): r for r in csv.DictReader(open('$tmp/again/results.csv'))}
assert [r['method'] for r in part] == ['spread', 'icp'] * 2, [r['method'] for r in part]
assert len(again) == 4
for r in part:
  assert r['msd_mm'] == again[key(r)]['msd_mm'] and r['volume_change_pct'] == again[key(r)]['volume_change_pct'], key(r)
j = json.load(open('$tmp/sample.json'))
assert j['cases'] == 2 and j['grid_cases'] == 20
assert 'a seeded uniform sample' in open('$tmp/sample/RESULTS.md').read()"
# --sessions: the regime of treatment sessions. The prostate unmoved (case 1: noise
# alone) and shifted 5 mm (case 5), the cube rotated 2 mm (case 44): ours within 0.1 mm of
# the undeformed organ where nothing moved, and far better where it moved rigidly.
"$bin" --quiet bench fit --sessions --defaults-only --cases 1,5,44 --methods spread,tps --out "$tmp/sessions" > "$tmp/sessions.json" 2> /dev/null
check bench.fit_sessions_do_no_harm /usr/bin/python3 -c "
import csv, json
rows = {(r['method'], r['case']): r for r in csv.DictReader(open('$tmp/sessions/results.csv'))}
ours = lambda c: float(rows[('spread', c)]['msd_mm']); unmoved = lambda c: float(rows[('spread', c)]['msd_undeformed_mm'])
assert rows[('spread', '1')]['family'] == 'shift' and float(rows[('spread', '1')]['magnitude_mm']) == 0
assert rows[('spread', '44')]['family'] == 'rotate' and rows[('spread', '44')]['shape'] == 'cube'
assert ours('1') <= unmoved('1') + 0.1, (ours('1'), unmoved('1'))
assert unmoved('5') > 2 and ours('5') < 0.5 * unmoved('5'), (ours('5'), unmoved('5'))
assert ours('44') < unmoved('44'), (ours('44'), unmoved('44'))
j = json.load(open('$tmp/sessions.json'))
assert j['grid_cases'] == 140 and j['do_no_harm']['spread']['worse_than_undeformed_plus_0_1mm'] == 0, j['do_no_harm']
assert j['do_no_harm']['spread_worse_than_tps'] == 0
assert '## Do no harm' in open('$tmp/sessions/RESULTS.md').read()"
# An unknown method or a case beyond the grid: a one-line usage error (exit 2) that
# names the option and makes no folder.
"$bin" bench fit --quick --methods spread,tsp --out "$tmp/none" > /dev/null 2> "$tmp/none.err"
check bench.fit_unknown_method_refused test $? -eq 2 -a "$(grep -c . "$tmp/none.err")" -eq 1 -a ! -e "$tmp/none"
check bench.fit_unknown_method_named grep -q -- "--methods: unknown method 'tsp'" "$tmp/none.err"
"$bin" bench fit --quick --cases 3,21 --out "$tmp/beyond" > /dev/null 2> "$tmp/beyond.err"
check bench.fit_case_beyond_the_grid_refused test $? -eq 2 -a "$(grep -c . "$tmp/beyond.err")" -eq 1 -a ! -e "$tmp/beyond"
check bench.fit_case_beyond_the_grid_named grep -q -- "--cases: no case 21" "$tmp/beyond.err"
fi

if [[ $part == stability ]]; then
# The 30 mm cube twisted by 38 degrees at its ends (corners moved 10 to 14 mm), seen on
# half its surface by 20 and 50 points (0.5 mm noise): a twist is three shears (y z y),
# which the global map holds since 2026-11 (HD95 3.5 to 4.2 mm with x y z alone; now
# 2.5, MSD 0.77 and 0.68 mm).
"$bin" --quiet bench fit --cases 723,729 --methods spread --out "$tmp/twist" > /dev/null 2>&1
check bench.fit_follows_a_twist_seen_from_one_side /usr/bin/python3 -c "
import csv
rows = list(csv.DictReader(open('$tmp/twist/results.csv')))
assert [(r['family'], r['magnitude_mm'], r['points']) for r in rows] == [('twist', '10', '20'), ('twist', '10', '50')], rows
for r in rows:
    assert float(r['msd_mm']) < 0.85 and float(r['hd95_mm']) < 3.0 and abs(float(r['volume_change_pct'])) < 1.0, r"
"$bin" --quiet bench stability --out "$tmp/stab" > "$tmp/stab.json" 2> /dev/null
check bench.stability_every_row_passes test $? -eq 0
check bench.stability_table /usr/bin/python3 -c "
import csv, json
rows = list(csv.DictReader(open('$tmp/stab/stability.csv')))
assert len(rows) == 22 and all(r['pass'] == 'true' for r in rows)
assert {r['outcome'] for r in rows} <= {'converged', 'stopped', 'refused'}
assert json.load(open('$tmp/stab.json'))['all_pass']
# The spread fit never leaves a folding or swollen organ: a local stage that folds it or
# changes its volume beyond 1% (the 0.3 mm particles of tiny_radius swell it by 1.3% under
# 0.5 mm noise) is undone to the global stage's, which keeps the volume and, under this
# noise, explains the points: converged.
tiny = [r for r in rows if r['case'] == 'tiny_radius' and r['method'] == 'spread'][0]
assert abs(float(tiny['volume_change_pct'])) < 0.5 and 'organ kept' in tiny['reason'], tiny
assert tiny['outcome'] == 'converged' and 'which explains the points' in tiny['reason'], tiny
assert all(abs(float(r['volume_change_pct'])) <= 1.0 for r in rows if r['method'] == 'spread'), rows
assert not any('folds' in r['reason'] for r in rows if r['method'] == 'spread'), rows"
fi
if [[ $part == stability ]]; then
# bench scale on the prostate: a planning and a session run, each stage timed with its
# memory; the update a clinic waits for is the sum of its three stages.
"$bin" --quiet bench scale --cases prostate --out "$tmp/scale" > "$tmp/scale.json" 2> "$tmp/scale.err"
check bench.scale_runs test $? -eq 0
check bench.scale_stages /usr/bin/python3 -c "
import json
j = json.load(open('$tmp/scale.json'))
assert j == json.load(open('$tmp/scale/scale.json'))
[c] = j['cases']
assert c['case'] == 'prostate' and c['particles'] > 500 and 30 < c['volume_cm3'] < 40, c
plan, [s] = c['planning'], c['sessions']
assert {'phantom', 'ct', 'organ', 'model', 'export'} <= set(plan['stages']), plan['stages'].keys()
assert {'planning_model', 'points', 'fit', 'truth', 'export', 'report'} <= set(s['stages']), s['stages'].keys()
for run in (plan, s):
  walls = [st['wall_s'] for st in run['stages'].values()]
  assert all(w >= 0 for w in walls) and sum(walls) <= run['wall_s'], run
  assert all(0 < st['peak_memory_mib'] <= run['peak_memory_mib'] < 1024 for st in run['stages'].values()), run
assert abs(s['update_s'] - sum(s['stages'][k]['wall_s'] for k in ('planning_model', 'points', 'fit'))) < 1e-9
assert s['points'] == 87 and s['truth_msd_mm'] < 1.0 and c['relax_particle_steps_per_s'] > 0 and s['fit_particle_steps_per_s'] >= s['fit_wall_particle_steps_per_s'] > 0
assert s['fit_rate_runs'] == 1 and s['fit_rate_steps_s'] > 0, s  # timed once: not in the flatness
assert 'fit_step_flatness' not in j and 'targets' not in c, j  # one case under 5,000 particles"
"$bin" bench scale --cases prostate,bladder --out "$tmp/noscale" > /dev/null 2> "$tmp/noscale.err"
check bench.scale_unknown_case_refused test $? -eq 2 -a "$(grep -c . "$tmp/noscale.err")" -eq 1 -a ! -e "$tmp/noscale"
check bench.scale_unknown_case_named grep -q -- "--cases: unknown case 'bladder'" "$tmp/noscale.err"
fi
echo "$passed passed, $failed failed"
[[ $failed -eq 0 ]]
