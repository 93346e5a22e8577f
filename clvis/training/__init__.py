"""Training of the post family's networks: a layer above the families, like
the CLI, since it renders its pairs with the raster and iso families and
trains clvis.post.nets (``clvis train``; the ``train`` extra).

- :mod:`clvis.training.data`: the training and held-out pairs;
- :mod:`clvis.training.train`: training, ONNX export, fp16/int8 variants and
  the model card.
"""
