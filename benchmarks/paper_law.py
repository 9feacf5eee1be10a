"""A plain numpy transcription of the paper's control law, the baseline the benchmarks compare
``geoctl_ros.core.law.control`` against (issue 10). Written as one would from the paper, with a
Python loop over the cones and no precomputation; not used by the package.

Notation as in the paper (Props. 1-5): A, e_RA; B_i, e_RB,i per cone; Psi = A (1 + sum (B_i - 1));
e_R = e_RA (1 + sum (B_i - 1)) + A sum e_RB,i; u = -k_R e_R - k_Omega Omega + Omega x J Omega
- Delta_bar; Delta_bar' = k_Delta (Omega + c e_R). Valid outside the cones only.
"""
import numpy as np


def hat(x):
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


def vee(M):
    return np.array([M[2, 1], M[0, 2], M[1, 0]])


class PaperLaw:
    def __init__(self, J, G, k_R, k_Omega, k_Delta, c, alpha, r, cone_axes, cone_angles):
        self.J, self.G = np.asarray(J), np.diag(G)
        self.k_R, self.k_Omega, self.k_Delta, self.c, self.alpha = k_R, k_Omega, k_Delta, c, alpha
        self.r = np.asarray(r, dtype=float) / np.linalg.norm(r)
        self.cones = [(np.asarray(v, dtype=float) / np.linalg.norm(v), th)
                      for v, th in zip(cone_axes, cone_angles)]
        self.delta_bar = np.zeros(3)

    def step(self, R, Omega, dt, R_d=np.eye(3)):
        G = self.G
        A = 0.5 * np.trace(G @ (np.eye(3) - R_d.T @ R))
        e_RA = 0.5 * vee(G @ R_d.T @ R - R.T @ R_d @ G)
        B_sum, e_RB_sum = 0.0, np.zeros(3)
        for v, theta in self.cones:
            s = self.r @ R.T @ v
            B_sum += 1.0 - np.log((np.cos(theta) - s) / (1.0 + np.cos(theta))) / self.alpha - 1.0
            e_RB_sum += hat(R.T @ v) @ self.r / (self.alpha * (s - np.cos(theta)))
        e_R = e_RA * (1.0 + B_sum) + A * e_RB_sum
        u = (-self.k_R * e_R - self.k_Omega * Omega + np.cross(Omega, self.J @ Omega)
             - self.delta_bar)
        self.delta_bar = self.delta_bar + dt * self.k_Delta * (Omega + self.c * e_R)
        return u, A * (1.0 + B_sum)
