"""The tiny training setting that the end-to-end tests share: the synthetic split at 192×64, the
small ResNet-10 from scratch, batch 2, no loader workers (each file adds its own logging keys)."""

TINY_MODEL = [
    "data.split=synth",
    "model.height=64",
    "model.width=192",
    "model.num_layers=10",
    "model.pretrained=false",
    "train.batch_size=2",
    "data.num_workers=0",
]
