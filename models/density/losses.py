"""Training losses for point-supervised density maps: Bayesian Loss (Ma et al., ICCV 2019) and an MSE option.

Both take a predicted density of shape (N, 1, h, w) at ``stride`` input pixels per cell and, per image, the
annotated head points as a tensor of shape (K, 2) of (u, v) input pixels (K may be 0).
"""

from __future__ import annotations

import enum
import math

import torch
from torch.nn import functional


class LossKind(str, enum.Enum):
    """Which loss trains the network."""

    BAYESIAN = "bayesian"
    """Bayesian Loss with the background term ("Bayesian+"): the expected count of each head is one."""
    MSE = "mse"
    """Pixel-wise squared error against Gaussian-smoothed head points (the classic MCNN target)."""
    MSE_MARGIN = "mse-margin"
    """MSE plus hinges at the deployed occupancy threshold: empty ground below it, head cores above it."""


OCCUPANCY_THRESHOLD = 0.01
"""People per cell at which the shipped perception config calls a cell occupied (``occupancy.density_threshold``)."""


def _cell_centres(h: int, w: int, stride: int, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    v = (torch.arange(h, device=device, dtype=torch.float32) + 0.5) * stride
    u = (torch.arange(w, device=device, dtype=torch.float32) + 0.5) * stride
    return u, v


def bayesian_loss(
    density: torch.Tensor,
    points: list[torch.Tensor],
    stride: int,
    sigma_px: float = 4.0,
    background_px: float | None = 16.0,
) -> torch.Tensor:
    """Bayesian Loss: sum over heads of |1 - E[count of head n]|, plus |E[background count]|, averaged per image.

    The posterior of cell m belonging to head n is a softmax over heads of -|x_m - z_n|^2 / (2 sigma^2). With
    ``background_px`` = d, each cell also gets a background "head" at distance max(d - |x_m - z_nearest|, 0), whose
    expected count must be zero; this keeps density off the ground between people. Images without people
    contribute |sum of density|.

    Parameters
    ----------
    density : Tensor, shape (N, 1, h, w)
        Predicted people per cell.
    points : list of N Tensors, shape (K_i, 2)
        Head points (u, v) in input pixels.
    stride : int
        Input pixels per density cell.
    sigma_px : float
        Spread of the likelihood around each head, input pixels.
    background_px : float or None
        Distance d of the background model, input pixels; None disables the background term.
    """
    n, _, h, w = density.shape
    u, v = _cell_centres(h, w, stride, density.device)
    total = density.new_zeros(())
    for i in range(n):
        d = density[i, 0].reshape(-1)
        pts = points[i]
        if pts.numel() == 0:
            total = total + d.sum().abs()
            continue
        du = (pts[:, 0:1] - u[None, :]) ** 2  # (K, w)
        dv = (pts[:, 1:2] - v[None, :]) ** 2  # (K, h)
        dist2 = (dv[:, :, None] + du[:, None, :]).reshape(pts.shape[0], -1)  # (K, h*w)
        logits = -dist2 / (2.0 * sigma_px**2)
        target = torch.ones(pts.shape[0], device=density.device)
        if background_px is not None:
            nearest = dist2.min(dim=0, keepdim=True).values.clamp_min(0.0).sqrt()
            bg_dist2 = (background_px - nearest).clamp_min(0.0) ** 2
            logits = torch.cat([logits, -bg_dist2 / (2.0 * sigma_px**2)], dim=0)
            target = torch.cat([target, target.new_zeros(1)])
        posterior = torch.softmax(logits, dim=0)
        expected = posterior @ d
        total = total + (target - expected).abs().sum()
    return total / n


def point_density_target(points: list[torch.Tensor], h: int, w: int, stride: int, sigma_px: float) -> torch.Tensor:
    """Density targets of shape (N, 1, h, w): each head a Gaussian of ``sigma_px`` summing to one."""
    device = points[0].device if points else torch.device("cpu")
    u, v = _cell_centres(h, w, stride, device)
    sigma_cells = sigma_px
    out = torch.zeros(len(points), 1, h, w, device=device)
    for i, pts in enumerate(points):
        if pts.numel() == 0:
            continue
        gu = torch.exp(-((pts[:, 0:1] - u[None, :]) ** 2) / (2 * sigma_cells**2))  # (K, w)
        gv = torch.exp(-((pts[:, 1:2] - v[None, :]) ** 2) / (2 * sigma_cells**2))  # (K, h)
        g = gv[:, :, None] * gu[:, None, :]
        g = g / g.sum(dim=(1, 2), keepdim=True).clamp_min(1e-12)
        out[i, 0] = g.sum(dim=0)
    return out


def mse_loss(density: torch.Tensor, points: list[torch.Tensor], stride: int, sigma_px: float = 4.0) -> torch.Tensor:
    """Sum of squared errors against :func:`point_density_target`, averaged per image, scaled by the cell count
    so that its magnitude is comparable across crop sizes."""
    n, _, h, w = density.shape
    target = point_density_target(points, h, w, stride, sigma_px)
    return functional.mse_loss(density, target, reduction="sum") / n * math.sqrt(h * w)


def mse_margin_loss(
    density: torch.Tensor,
    points: list[torch.Tensor],
    stride: int,
    sigma_px: float = 4.0,
    threshold: float = OCCUPANCY_THRESHOLD,
    weight: float = 30.0,
) -> torch.Tensor:
    """:func:`mse_loss` plus two hinges that speak the occupancy map's language.

    MSE leaves a small positive floor on textured ground that the low occupancy threshold turns into "people".
    Here every *background* cell (target below a tenth of ``threshold``: about three sigmas from every head) pays
    linearly for each bit of density above half the threshold, and every *head core* cell (target at least twice
    the threshold) pays for each bit below twice the threshold. Each hinge is the mean over its cells in units of
    the threshold, times ``weight``, so that neither empty crops nor crowded ones dominate.
    """
    n, _, h, w = density.shape
    target = point_density_target(points, h, w, stride, sigma_px)
    mse = functional.mse_loss(density, target, reduction="sum") / n * math.sqrt(h * w)
    background = (target < 0.1 * threshold).float()
    core = (target >= 2.0 * threshold).float()
    over = (functional.relu(density - 0.5 * threshold) * background).sum() / background.sum().clamp_min(1.0)
    under = (functional.relu(2.0 * threshold - density) * core).sum() / core.sum().clamp_min(1.0)
    return mse + weight * (over + under) / threshold


def density_loss(
    kind: LossKind, density: torch.Tensor, points: list[torch.Tensor], stride: int, sigma_px: float
) -> torch.Tensor:
    """The configured loss."""
    if kind is LossKind.BAYESIAN:
        return bayesian_loss(density, points, stride, sigma_px)
    if kind is LossKind.MSE_MARGIN:
        return mse_margin_loss(density, points, stride, sigma_px)
    return mse_loss(density, points, stride, sigma_px)
