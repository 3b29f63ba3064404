"""lfdt.optim: its optimizers start without importing torch's compiler, and step to the same bits as with it."""

import subprocess
import sys

import pytest

TRAIN = """
import sys
{first}
import lfdt.optim
import torch

torch.manual_seed(0)
net = torch.nn.Sequential(torch.nn.Linear(5, 16), torch.nn.Tanh(), torch.nn.Linear(16, 2))
opt = lfdt.optim.Adam(net.parameters(), lr=1e-2{kwargs})
x, y = torch.randn(64, 5), torch.randn(64, 2)
for _ in range(20):
    opt.zero_grad()
    torch.nn.functional.mse_loss(net(x), y).backward()
    opt.step()
state = opt.state_dict()
opt.load_state_dict(state)
print(type(opt).__name__, "torch._dynamo" in sys.modules)
print(b"".join(p.detach().numpy().tobytes() for p in net.parameters()).hex())
print(b"".join(v.numpy().tobytes() for s in state["state"].values() for v in s.values()
               if isinstance(v, torch.Tensor)).hex())
"""
"""Train a small net with lfdt.optim.Adam; print the optimizer's class, whether the compiler was imported, and the
bits of the weights and of the optimizer's state."""

# torch's own wrapping, as it is without lfdt.optim: the compiler imported, each wrapped method's cache filled
WITH_COMPILER = """
import torch, torch._dynamo
torch.optim.SGD(torch.nn.Linear(1, 1).parameters(), lr=0.1).state_dict()
torch.optim.SGD(torch.nn.Linear(1, 1).parameters(), lr=0.1).load_state_dict(
    torch.optim.SGD(torch.nn.Linear(1, 1).parameters(), lr=0.1).state_dict())
torch.optim.SGD(torch.nn.Linear(1, 1).parameters(), lr=0.1).zero_grad()
"""


def _train(first: str, kwargs: str) -> list[str]:
    proc = subprocess.run([sys.executable, "-c", TRAIN.format(first=first, kwargs=kwargs)], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout.split()


@pytest.mark.parametrize("kwargs", ["", ", weight_decay=1e-4"], ids=["numpy-adam", "torch-adam"])
def test_an_optimizer_starts_without_the_compiler_and_steps_to_the_same_bits(kwargs):
    """lfdt.optim.Adam with NumPy arithmetic (every CPU training stage's) is built, stepped, saved and loaded without
    importing torch._dynamo (about 1.5 s in every training process); its weights and state, and those of torch's
    Adam (an option only torch has; its own step imports the compiler), are the same bits as in a process where
    torch wrapped the optimizer's methods as it does by default, the compiler loaded."""
    name, compiler, weights, state = _train("", kwargs)
    assert name == ("_NumpyAdam" if not kwargs else "Adam")
    if not kwargs:
        assert compiler == "False", "building or using lfdt.optim's NumPy Adam imported torch._dynamo"
    name2, compiler2, weights2, state2 = _train(WITH_COMPILER, kwargs)
    assert compiler2 == "True"
    assert (name2, weights2, state2) == (name, weights, state)
