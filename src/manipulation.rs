//! Manipulation (000 Part V): force estimation, object characterisation, distributed-parameter beam observers.
