"""Write scripts/optimum/<tag>.yml: occ_s2.yml with a few keys changed (issue 38, Campaign 3 screens).

    python scripts/optimum/make_screens.py [TAG ...]   # default: every tag of SCREENS
"""
import copy
import sys
from pathlib import Path

import yaml

D = Path(__file__).resolve().parent
ENV = "ContinuumGym/OcclusionAvoidance-v0"
base = yaml.safe_load((D / "occ_s2.yml").read_text())[ENV]
SCREENS = {
 "occ_g99": ("gamma 0.98 -> 0.99", {"gamma": 0.99}),
 "occ_lam98": ("gae_lambda 0.95 -> 0.98", {"gae_lambda": 0.98}),
 "occ_ep10": ("n_epochs 5 -> 10", {"n_epochs": 10}),
 "occ_net128": ("policy_kwargs.net_arch [64, 64] -> [128, 128]", {"policy_kwargs.net_arch": [128, 128]}),
 "occ_net256": ("policy_kwargs.net_arch [64, 64] -> [256, 256]", {"policy_kwargs.net_arch": [256, 256]}),
 "occ_b4096": ("n_envs 256 -> 512, batch_size 1024 -> 4096", {"n_envs": 512, "batch_size": 4096}),
 "occ_lr1e4": ("learning_rate 3e-4 -> 1e-4", {"learning_rate": 0.0001}),
 "occ_nosde": ("use_sde true -> false, log_std_init -2.39 -> -2.41 (= ln(0.18 / 2): the same noise in residual units "
               "as a plain diagonal Gaussian)", {"use_sde": False, "sde_sample_freq": None, "policy_kwargs.log_std_init": -2.41}),
 "occ_vg80": ("env_kwargs.visibility_guard 0.69 -> 0.80 (looser guard: more room for the residual)", {"env_kwargs.visibility_guard": 0.8}),
 "occ_ep20": ("n_epochs 5 -> 20", {"n_epochs": 20}),
 "occ_ep10n128": ("n_epochs 5 -> 10 and policy_kwargs.net_arch [64, 64] -> [128, 128]",
                   {"n_epochs": 10, "policy_kwargs.net_arch": [128, 128]}),
 "occ_vg60": ("env_kwargs.visibility_guard 0.69 -> 0.60 (tighter guard)", {"env_kwargs.visibility_guard": 0.6}),
 "occ_act0": ("env_kwargs.reward_weights {action: 0.0} (default 0.01)", {"env_kwargs.reward_weights": {"action": 0.0}}),
 "occ_hold": ("env_kwargs.task mixed -> hold (train on hold starts only)", {"env_kwargs.task": "hold"}),
}
def apply(block, changes):
    block = copy.deepcopy(block)
    for key, value in changes.items():
        *path, last = key.split(".")
        d = block
        for p in path:
            d = d.setdefault(p, {})
        if value is None:
            d.pop(last, None)
        else:
            d[last] = value
    return block
tags = sys.argv[1:] or list(SCREENS)
for tag in tags:
    what, changes = SCREENS[tag]
    block = apply(base, changes)
    head = (f"# Issue 38, Campaign 3 screen `{tag}` (docs/optimum-experiments.md): scripts/optimum/occ_s2.yml with only\n"
            f"# {what}. 1M steps.\n"
            f"# Use: python scripts/optimum/run_queue.py {tag}:0 "
            f"(or continuum-gym train --env {ENV} --hyperparams scripts/optimum/{tag}.yml)\n")
    body = yaml.safe_dump({ENV: block}, sort_keys=False, default_flow_style=None, width=120)
    (D / f"{tag}.yml").write_text(head + body)
    print(tag)
