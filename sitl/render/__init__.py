"""Rendering the SITL world through pyrender, offscreen (EGL: Mesa's llvmpipe on CPU, or a GPU driver)."""
