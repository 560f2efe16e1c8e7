"""PNG figures: the demo's (`figures`) and `cclog plot` of any store (`store`).
matplotlib is imported only when a figure is drawn."""
