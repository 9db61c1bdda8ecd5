"""Run from the repository root after unpacking both humanoid archives: PYTHONPATH=. python docs/results/exp4/scan_diag/gains.py.
Per treatment, the first layer's gain per metre on the torso height: the blind input obs[0] (|w0| / std0) and the scan's common mode (the sum over
the 153 scan points of w / std), mean over units and the 10 walkers."""
import numpy as np
from jaxterrain import rl
from jaxterrain.rl.networks import stats_std
B = 45
def W(p): return np.asarray(p.params["policy"]["params"]["mlp"]["hidden_0"]["kernel"])
base = rl.load_policy(rl.base_policy_dir('humanoid', 'perceptive'))
s0 = np.asarray(stats_std(base.normaliser))
print('blind torso-height input: std %.4f m; base gain |w0|/std per m: mean over units %.2f' % (s0[0], np.abs(W(base)[0] / s0[0]).mean()))
for obs in ['perceptive', 'blind']:
    for t in ['mixed-map', 'steps-map', 'mixed-dr', 'mixed-plr', 'mixed-levels']:
        g_cm, g_h0, shape = [], [], []
        for k in range(10):
            p = rl.load_policy(f'runs/exp4/train/humanoid-{obs}/{t}/policies/trial_{k}')
            w, s = W(p), np.asarray(stats_std(p.normaliser))
            g_h0.append(np.abs(w[0] / s[0]).mean())
            if obs == 'perceptive':
                ws = w[B:] / s[B:, None]           # [153, 32] gain per metre of each scan point
                cm = ws.sum(0)                      # gain per metre of a uniform shift (torso height)
                g_cm.append(np.abs(cm).mean())
                # effective gain on the torso height above terrain: blind input 0 (+) and the scan's common mode (-)
                shape.append(np.abs(w[0] / s[0] - cm).mean())
        if obs == 'perceptive':
            print(f'{obs:10s} {t:12s} blind h0 gain {np.mean(g_h0):6.2f}/m  scan common-mode gain {np.mean(g_cm):6.2f}/m '
                  f'[{np.min(g_cm):.1f}, {np.max(g_cm):.1f}]  total torso-height gain {np.mean(shape):6.2f}/m')
        else:
            print(f'{obs:10s} {t:12s} blind h0 gain {np.mean(g_h0):6.2f}/m')
