//! Measured and simulated records: CSV with `#` comments, header `t,u|u1..uk,y|y1..yn`.
