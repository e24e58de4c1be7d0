# act_set_warnings(target): the project's warning set; -Werror when ACT_WERROR is on (CI).
function(act_set_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor
                         -Wcast-align -Wunused -Woverloaded-virtual)
  if(ACT_WERROR)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()
