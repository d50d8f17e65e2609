//! Distributed-parameter beam (000 eq. 9) driven by the piezo load.
