"""Print the per-clip table of docs/force_shares.md (run from the repository root):

    .venv/bin/python docs/make_force_shares.py [MOCAP_DIR]
"""
import sys
from pathlib import Path

from froude import load_bvh
from froude.machine.fit import fit_machine_detailed

CLIPS = ["09_01", "09_02", "09_03", "09_04", "09_05", "09_06", "09_07", "09_08", "02_03"]
mocap = Path(sys.argv[1] if len(sys.argv) > 1 else "../shared/data/mocap")
print("| clip | periodicity | COM RMS [cm] | stance [s] | flight [s] | speed [m/s] | K | peak Fz [BW] "
      "| COM drop [cm] | flight residual [BW RMS] | along-leg share [%] | vertical share [%] "
      "| along-leg share² [%] | vertical share² [%] |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
for c in CLIPS:
    res = fit_machine_detailed(load_bvh(mocap / f"{c}.bvh"))
    m = res.machine
    ref, q = m.reference, m.quality
    full = [s for s in m.stances if not s["partial"]]
    pk = [s["peak_vertical_force_bw"] for s in full]
    drop = [100 * s["com_drop_m"] for s in full]
    sh = ref["shares"]
    print(f"| {c} | {m.periodicity:.0e} | {100 * q['com_rms_m']:.2f} | {m.t_stance * m.time_unit:.3f} | "
          f"{m.t_flight * m.time_unit:.3f} | {m.mean_speed * m.speed_unit:.2f} | {m.K:.1f} | "
          f"{min(pk):.2f}-{max(pk):.2f} (machine {m.peak_force:.2f}) | {min(drop):.1f}-{max(drop):.1f} | "
          f"{ref['flight_residual_bw']:.3f} | {100 * sh['leg']:.1f} | {100 * sh['vertical']:.1f} | "
          f"{100 * sh.get('leg_sq', float('nan')):.1f} | {100 * sh.get('vertical_sq', float('nan')):.1f} |")
