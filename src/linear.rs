//! Hammerstein linear dynamics (004 eq. 8): continuous poles and zeros discretised exactly (ZOH) or by prewarped bilinear transform.
